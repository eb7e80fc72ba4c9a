# The zenoh router, zenohd, at the version of the zenoh crate meshless is
# built with (Cargo.lock), two ways to the same image:
#
#   docker build -f deploy/zenohd.Dockerfile --target runtime -t meshless-zenohd:1.10.2 .
#       compiles zenohd from crates.io in a Rust stage (what a
#       registry-backed CI does);
#   docker build -f deploy/zenohd.Dockerfile --target prebuilt -t meshless-zenohd:1.10.2 .
#       copies target/zenohd/zenohd, a zenohd the host compiled with the
#       same version and features (same glibc: build it on Debian
#       bookworm). scripts/harness does this, keeping the compiled router
#       in a cache outside the clone, so a machine compiles it once
#       rather than every time its images are built anew.
#
# Both from the repository root. Its configuration is mounted
# (deploy/config/zenohd.json5 in compose, a ConfigMap in deploy/k8s). That
# configuration loads no plugin, so none is built (the REST and storage
# plugins are separate libraries), and zenohd is built with the transports
# meshless speaks, TCP and TLS, and user and password authentication:
# QUIC, WebSocket, UDP, Unix sockets, public-key authentication and
# compression stay out (ZENOHD_FEATURES adds them back), which also
# shortens the build. Without a container registry, deploy/base-images
# first creates the base images.
#
# The stages run in file order up to the target with Docker's classic
# builder, so `prebuilt` comes before the Rust stage it does not need.
ARG RUST_IMAGE=rust:bookworm
ARG RUNTIME_IMAGE=debian:bookworm-slim

FROM ${RUNTIME_IMAGE} AS base
RUN useradd --system --uid 10001 --user-group --no-create-home zenohd
COPY deploy/config/zenohd.json5 /etc/zenohd/zenohd.json5
ENV PATH=/opt/zenohd:$PATH
USER zenohd
# 7447: zenoh (TCP), for servers and subscribers alike.
EXPOSE 7447
# No plugin, so no HTTP endpoint to ask: the router is healthy when its
# port accepts a connection (bash's /dev/tcp, nothing to install).
HEALTHCHECK --interval=5s --timeout=3s --start-period=5s --retries=5 \
  CMD ["bash", "-c", "exec 3<>/dev/tcp/127.0.0.1/7447"]
ENTRYPOINT ["zenohd", "-c", "/etc/zenohd/zenohd.json5"]

FROM base AS prebuilt
# The classic builder also runs this stage on its way to `runtime`, where
# target/ holds no router: the bracketed name is a pattern that may match
# nothing, and the configuration beside it keeps the COPY from having no
# source at all.
COPY deploy/config/zenohd.json5 target/zenohd/zenoh[d] /opt/zenohd/

FROM ${RUST_IMAGE} AS build
ARG ZENOHD_VERSION=1.10.2
ARG ZENOHD_FEATURES=zenoh/transport_tcp,zenoh/transport_tls,zenoh/auth_usrpwd
RUN cargo install zenohd --version "=${ZENOHD_VERSION}" --locked --root /out \
      --no-default-features --features "${ZENOHD_FEATURES}"

FROM base AS runtime
COPY --from=build /out/bin/zenohd /opt/zenohd/zenohd
