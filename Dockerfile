# fcmaster in a container: slim, non-root (user fcmaster, in dialout), config mounted
# read-only, the serial adapter passed with --device, JSON logs (on stderr: `docker logs`
# shows them). README.md "Running with Docker" has the whole story.
#
#   docker build -t fcmaster .
#   docker run -d --name fcmaster --restart unless-stopped --read-only --stop-timeout 75 \
#       --device /dev/ttyUSB0 \
#       -v "$PWD/plant.yaml:/etc/fcmaster/config.yaml:ro" \
#       -p 127.0.0.1:8080:8080 \
#       fcmaster run --config /etc/fcmaster/config.yaml
#   docker run --rm --network host fcmaster        # the demo, on http://127.0.0.1:8080/
#
# PYTHON_IMAGE may be any Debian-based image with python3 (>= 3.11) and its venv module.
ARG PYTHON_IMAGE=python:3.11-slim

FROM ${PYTHON_IMAGE} AS build
# A virtual environment, so the runtime stage takes the application and its dependencies
# in one COPY, without pip, the source tree or build leftovers.
RUN python3 -m venv /opt/fcmaster
WORKDIR /src
COPY pyproject.toml README.md ./
COPY fcmaster ./fcmaster
RUN /opt/fcmaster/bin/pip install --no-cache-dir --disable-pip-version-check . \
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
EXPOSE 8080
# `docker stop` sends SIGTERM: the daemon shuts down in order (on_shutdown) and exits 0,
# waiting for the drives' stops up to shutdown_timeout_s (60 s): --stop-timeout 75.
STOPSIGNAL SIGTERM
ENTRYPOINT ["fcmaster"]
CMD ["run"]
