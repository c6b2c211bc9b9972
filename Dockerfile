# bowloc service image: build on Debian bookworm with Debian's OpenCV 4.6,
# run on bookworm-slim with only the OpenCV runtime libraries the binary
# links (scripts/check-docker-runtime.sh checks this list against `ldd`).
#
#   docker build -t bowloc .      (podman: podman build --format docker -t bowloc .,
#                                  or the OCI format drops the HEALTHCHECK)
#   docker run -p 8080:8080 -v /path/to/maps:/data bowloc \
#     serve --vocab /data/vocab.bowvoc --map /data/map.bowmap
#
# The image holds no map: mount one (as above), or mount a dataset folder at
# /datasets/gardens-point to let the service bootstrap one into /data/default.

FROM rust:1.95-bookworm AS chef
RUN apt-get update \
 && apt-get install -y --no-install-recommends libopencv-dev pkg-config clang libclang-dev \
 && rm -rf /var/lib/apt/lists/*
RUN cargo install cargo-chef --locked --version ^0.1
WORKDIR /src

# The dependency recipe: changes only when Cargo.toml / Cargo.lock do.
FROM chef AS plan
COPY . .
RUN cargo chef prepare --recipe-path recipe.json

# Dependencies first, in their own cached layer (with .cargo/config.toml, which
# sets how the `opencv` crate links); then the project itself.
FROM chef AS build
COPY --from=plan /src/recipe.json recipe.json
COPY .cargo .cargo
RUN cargo chef cook --release --locked --recipe-path recipe.json --bin bowloc
COPY . .
# The release profile keeps line tables for backtraces (Cargo.toml); the image
# takes the binary without them (13 MB instead of 96, docs/service.md), symbols kept, so a
# backtrace still names its functions.
RUN cargo build --release --locked --bin bowloc \
 && strip --strip-debug -o /usr/local/bin/bowloc target/release/bowloc

FROM debian:bookworm-slim AS runtime
RUN apt-get update \
 && apt-get install -y --no-install-recommends libopencv-core406 libopencv-imgproc406 libopencv-imgcodecs406 libopencv-features2d406 libopencv-flann406 libopencv-calib3d406 \
 && rm -rf /var/lib/apt/lists/* \
 && useradd --system --uid 10001 --home-dir /srv/bowloc --create-home bowloc \
 && mkdir -p /data && chown bowloc /data \
 && ln -s /data /srv/bowloc/data
COPY --from=build /usr/local/bin/bowloc /usr/local/bin/bowloc
COPY config/default.toml /etc/bowloc/config.toml
WORKDIR /srv/bowloc
USER bowloc
# Inside the container listen on every interface. The default files
# (data/default/… relative to the working directory) land in /data/default
# through the link above; bootstrap builds them from /datasets/gardens-point.
ENV BOWLOC_SERVER__LISTEN=0.0.0.0:8080 \
    BOWLOC_SERVER__LOG_FORMAT=json \
    BOWLOC_BOOTSTRAP__DATASET=/datasets/gardens-point
EXPOSE 8080
# Healthy once ready (the map loaded); the start period covers a bootstrap.
HEALTHCHECK --interval=15s --timeout=5s --start-period=10m --retries=3 \
  CMD ["bowloc", "healthcheck", "--address", "127.0.0.1:8080", "--path", "/readyz"]
STOPSIGNAL SIGTERM
ENTRYPOINT ["bowloc"]
CMD ["serve", "--config", "/etc/bowloc/config.toml"]
