#!/usr/bin/env bash
# The server's sequence state under 10 000 distinct sequence names: resident
# memory (VmRSS from /proc) before and after, with caps of 1 000 and 10 000
# sequences (tests/sequences_memory.rs).
set -euo pipefail
cd "$(dirname "$0")/.."
cargo test --release --test sequences_memory -- --nocapture 2>&1 | grep -E '^cap |test result'
