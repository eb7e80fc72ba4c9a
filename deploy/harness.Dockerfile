# The headless test harness of deploy/compose.yaml: the multi-host suite
# (deploy/harness) with the Python client and the `meshless` command line
# (the Rust client, taken from the server image), run against the servers
# through the zenoh router. Built from the repository root:
#
#   docker build -f deploy/harness.Dockerfile -t meshless-harness .
#
# The `tools` target, Python with the package and the suite but not the
# server image, also makes the harness's throwaway certificates
# (deploy/harness/certs.py) before any server starts. The harness drives
# the Docker engine (stop, kill, disconnect containers) through the socket
# compose mounts at /var/run/docker.sock.
ARG RUNTIME_IMAGE=debian:bookworm-slim
ARG MESHLESS_IMAGE=meshless:0.1.0

FROM ${RUNTIME_IMAGE} AS tools
RUN apt-get update \
 && apt-get install --yes --no-install-recommends python3 python3-venv \
 && rm -rf /var/lib/apt/lists/*
ENV VIRTUAL_ENV=/opt/harness PATH=/opt/harness/bin:$PATH
RUN python3 -m venv /opt/harness
COPY deploy/harness/requirements.txt /src/deploy/harness/requirements.txt
RUN pip install --no-cache-dir --disable-pip-version-check -r /src/deploy/harness/requirements.txt
# The package builds its protocol code from proto/ (client/python/setup.py).
COPY proto /src/proto
COPY client/python /src/client/python
RUN pip install --no-cache-dir --disable-pip-version-check --no-build-isolation /src/client/python
COPY deploy/config /src/deploy/config
COPY deploy/harness /src/deploy/harness
WORKDIR /src

# Classic builds run the stages before their target in file order: this
# one comes after `tools`, which therefore builds without it.
FROM ${MESHLESS_IMAGE} AS meshless

FROM tools AS harness
COPY --from=meshless /opt/meshless/meshless /usr/local/bin/meshless
ENV MESHLESS_HARNESS=compose
ENTRYPOINT ["python3", "-m", "pytest", "-p", "no:cacheprovider", "-v", "deploy/harness"]
