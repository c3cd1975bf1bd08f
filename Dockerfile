# fcmaster: slim image, non-root user in dialout, JSON logs on stdout.
#   docker build -t fcmaster .
#   docker run --device /dev/ttyUSB0 -v $PWD/config/plant.yaml:/etc/fcmaster/config.yaml:ro \
#       -p 127.0.0.1:8080:8080 fcmaster run --config /etc/fcmaster/config.yaml
FROM python:3.11-slim AS build
WORKDIR /src
COPY pyproject.toml README.md ./
COPY fcmaster ./fcmaster
RUN pip wheel --no-cache-dir --wheel-dir /wheels .

FROM python:3.11-slim
RUN useradd --system --no-create-home --groups dialout fcmaster
COPY --from=build /wheels /wheels
RUN pip install --no-cache-dir /wheels/*.whl && rm -rf /wheels
COPY config /etc/fcmaster
USER fcmaster
ENV PYTHONUNBUFFERED=1
ENTRYPOINT ["fcmaster"]
CMD ["run"]
