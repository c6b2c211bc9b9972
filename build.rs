//! Compiles `proto/localize.proto` into Rust types with prost. The .proto is
//! parsed by `protox` (pure Rust), so no `protoc` is needed.

fn main() {
    let proto = "proto/localize.proto";
    println!("cargo:rerun-if-changed={proto}");
    let files = protox::compile([proto], ["proto"]).unwrap_or_else(|e| panic!("{proto}: {e}"));
    prost_build::Config::new()
        .compile_fds(files)
        .unwrap_or_else(|e| panic!("{proto}: {e}"));
}
