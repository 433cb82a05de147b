# syntax=docker/dockerfile:1
# Prometheus from Debian's archive, scraping fusiond (docker/compose.yaml, docker/prometheus.yml).
#   docker build -f docker/prometheus.Dockerfile -t fusion-prometheus:latest docker
FROM debian:bookworm-slim
ARG DEBIAN_FRONTEND=noninteractive
# Debian's package makes the system user "prometheus".
RUN apt-get update \
 && apt-get install -y --no-install-recommends prometheus \
 && rm -rf /var/lib/apt/lists/* \
 && mkdir -p /prometheus && chown prometheus:prometheus /prometheus
COPY prometheus.yml fusiond-alerts.yml /etc/prometheus/
USER prometheus
WORKDIR /prometheus
EXPOSE 9090
CMD ["prometheus", "--config.file=/etc/prometheus/prometheus.yml", \
     "--storage.tsdb.path=/prometheus", "--storage.tsdb.retention.time=15d", \
     "--web.listen-address=0.0.0.0:9090"]
