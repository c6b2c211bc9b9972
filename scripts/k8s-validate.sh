#!/usr/bin/env bash
# Validate the Kubernetes manifests (deploy/kubernetes): render the base and
# every overlay offline and check each resource against the OpenAPI schema of
# a pinned Kubernetes version, strictly, plus what ties them together
# (scripts/k8s_render.py says what). kubernetes-validate, jsonpatch and PyYAML
# (PyPI, pinned) are installed into target/k8s-venv on first use.
#
#   scripts/k8s-validate.sh [OUT_DIR]
#
# OUT_DIR (default: a temporary folder) receives each tree's config.toml.
# tests/deploy.rs runs this, so `make test` does.
set -euo pipefail
cd "$(dirname "$0")/.."
KUBERNETES_VERSION=1.31.0
venv=target/k8s-venv
pins=(kubernetes-validate==1.37.0 jsonpatch==1.47 pyyaml==6.0.3)
if ! "$venv/bin/python" -c 'import kubernetes_validate, jsonpatch, yaml' 2>/dev/null \
  || [ "$("$venv/bin/pip" freeze 2>/dev/null | grep -ciE '^(kubernetes-validate==1.37.0|jsonpatch==1.47|pyyaml==6.0.3)$')" != 3 ]; then
  python3 -m venv "$venv"
  "$venv/bin/pip" install -q "${pins[@]}"
fi
out=${1:-$(mktemp -d)}
mkdir -p "$out"
trees=(deploy/kubernetes/base deploy/kubernetes/overlays/*/)
"$venv/bin/python" scripts/k8s_render.py "$KUBERNETES_VERSION" "$out" "${trees[@]%/}"
