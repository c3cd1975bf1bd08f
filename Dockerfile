# fcmaster in a container: slim, non-root (user fcmaster, in dialout), config mounted
# read-only, the serial adapter passed with --device, JSON logs (on stderr: `docker logs`
# shows them). README.md "Running with Docker" has the whole story.
#
#   docker build -t fcmaster .
#   docker run -d --name fcmaster --restart unless-stopped --read-only --stop-timeout 75 \
#       --device /dev/ttyUSB0 \
#       -v "$PWD/plant.yaml:/etc/fcmaster/config.yaml:ro" \
#       -p 127.0.0.1:8080:8080 -p 127.0.0.1:5020:5020 \
#       fcmaster run --config /etc/fcmaster/config.yaml
#   docker run --rm --network host fcmaster        # the demo, on http://127.0.0.1:8080/
#
# Behind a private package index or a TLS-inspecting proxy (only the build stage uses them):
#   docker build --build-arg PIP_INDEX_URL=https://pypi.example.net/simple \
#       --build-arg CA_BUNDLE="$(cat proxy-ca.pem)" -t fcmaster .
#
# PYTHON_IMAGE may be any Debian-based image with python3 (>= 3.11) and its venv module.
ARG PYTHON_IMAGE=python:3.11-slim

FROM ${PYTHON_IMAGE} AS build
# pip reads PIP_INDEX_URL (and PIP_EXTRA_INDEX_URL, PIP_TRUSTED_HOST) from the environment,
# where a build argument is during RUN. CA_BUNDLE is PEM text: the proxy's or the index's CA,
# added to the system's certificates, which pip is then told to trust.
ARG PIP_INDEX_URL
ARG PIP_EXTRA_INDEX_URL
ARG PIP_TRUSTED_HOST
ARG CA_BUNDLE
RUN if [ -n "$CA_BUNDLE" ]; then \
        printf '%s\n' "$CA_BUNDLE" > /usr/local/share/ca-certificates/fcmaster-build.crt \
        && update-ca-certificates; \
    fi
# A virtual environment, so the runtime stage takes the application and its dependencies
# in one COPY, without pip, the source tree or build leftovers.
RUN python3 -m venv /opt/fcmaster
WORKDIR /src
COPY pyproject.toml README.md ./
COPY fcmaster ./fcmaster
# (An argument given empty is dropped: pip would take "" for an index.)
RUN { [ -n "$PIP_INDEX_URL" ] || unset PIP_INDEX_URL; } \
    && { [ -n "$PIP_EXTRA_INDEX_URL" ] || unset PIP_EXTRA_INDEX_URL; } \
    && { [ -n "$PIP_TRUSTED_HOST" ] || unset PIP_TRUSTED_HOST; } \
    && if [ -n "$CA_BUNDLE" ]; then export PIP_CERT=/etc/ssl/certs/ca-certificates.crt; fi \
    && /opt/fcmaster/bin/pip install --no-cache-dir --disable-pip-version-check . \
    && /opt/fcmaster/bin/pip uninstall --yes pip setuptools \
    && /opt/fcmaster/bin/fcmaster check --config /src/fcmaster/demo.yaml

FROM ${PYTHON_IMAGE}
# The serial device node keeps the host's group id: dialout is 20 on Debian and Ubuntu
# hosts; elsewhere add the device's group with --group-add (see README.md).
RUN useradd --system --no-create-home --home-dir /nonexistent --shell /usr/sbin/nologin \
        --groups dialout fcmaster
COPY --from=build /opt/fcmaster /opt/fcmaster
ENV PATH=/opt/fcmaster/bin:$PATH \
    PYTHONUNBUFFERED=1 \
    PYTHONDONTWRITEBYTECODE=1
USER fcmaster
# 8080: HTTP API, dashboard, /metrics; 5020: Modbus TCP (each only where the config listens).
EXPOSE 8080 5020
# Healthy while the HTTP API answers (GET /, which needs no token). The image has no curl:
# Python asks, past any HTTP_PROXY in the environment. A config that listens elsewhere sets
# FCMASTER_HEALTH_URL (-e); one without an http section runs with --no-healthcheck.
ENV FCMASTER_HEALTH_URL=http://127.0.0.1:8080/
HEALTHCHECK --interval=30s --timeout=5s --start-period=60s --retries=3 \
    CMD ["python3", "-c", "import os, urllib.request as r; r.build_opener(r.ProxyHandler({})).open(os.environ['FCMASTER_HEALTH_URL'], timeout=4)"]
# `docker stop` sends SIGTERM: the daemon shuts down in order (on_shutdown) and exits 0,
# waiting for the drives' stops up to shutdown_timeout_s (60 s): --stop-timeout 75.
STOPSIGNAL SIGTERM
ENTRYPOINT ["fcmaster"]
CMD ["run"]
