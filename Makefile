# The two quick-start commands: `make run` and `make test`.
.PHONY: setup build run test bench openapi

setup:
	@bash scripts/setup.sh

build: setup
	cargo build --release

# Serve on the default map (built from ../shared/datasets if missing).
run: build
	./target/release/bowloc serve --config config/default.toml

# Unit, integration and curl-suite tests, then the API docs built with
# every rustdoc warning (a broken link) an error.
test: setup
	cargo test --release
	RUSTDOCFLAGS="-D warnings" cargo doc --release --no-deps

bench: setup
	cargo bench

# Regenerate the committed API document after changing the API.
openapi: build
	./target/release/bowloc openapi > docs/openapi.json
