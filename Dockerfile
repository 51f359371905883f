# monocap service image: build with the Rust toolchain, run on a slim Debian with
# ffmpeg (the fallback decoder for codecs monocap does not read itself).
#   docker build -t monocap .
#   docker run --rm -v monocap-data:/data monocap keys create --name me   # prints a token
#   docker run -d -p 8080:8080 -v monocap-data:/data monocap
# The container listens on 0.0.0.0, so it needs an API key (the service refuses to
# run open on a public address).

FROM rust:1.95-bookworm AS build
WORKDIR /src
COPY . .
RUN cargo build --release --locked --bin monocap

FROM debian:bookworm-slim
RUN apt-get update \
    && apt-get install -y --no-install-recommends ffmpeg curl ca-certificates \
    && rm -rf /var/lib/apt/lists/* \
    && useradd --system --uid 10001 --user-group --home-dir /data --no-create-home monocap \
    && mkdir /data && chown monocap:monocap /data
COPY --from=build /src/target/release/monocap /usr/local/bin/monocap
USER monocap
WORKDIR /data
VOLUME ["/data"]
ENV MONOCAP_DATA_DIR=/data MONOCAP_LISTEN=0.0.0.0:8080
EXPOSE 8080
HEALTHCHECK --interval=30s --timeout=3s --start-period=10s \
    CMD curl -fsS http://127.0.0.1:8080/healthz || exit 1
STOPSIGNAL SIGTERM
ENTRYPOINT ["monocap"]
CMD ["serve"]
