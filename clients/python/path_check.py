#!/usr/bin/python3
"""Checks a straight path through fusiond's map for collisions, as a planner would.

Samples the segment from START to GOAL (world frame, metres) every half voxel, optionally
with a ring of points at --radius around it, asks fusiond for their occupancy in batches
(QueryPoints) and reports the first occupied sample. Unknown space counts as an obstacle with
--unknown-is-obstacle.

Exit status: 0 the path is clear, 1 it collides, 2 usage or connection error.

A fusiond with TLS and tokens (docs/security.md): --tls-ca (the CA of its certificate),
--tls-cert / --tls-key (mutual TLS), --token-file (first line: the bearer token), or the
environment variables FUSION_TLS_CA, FUSION_TLS_CERT, FUSION_TLS_KEY, FUSION_TOKEN_FILE.

Stubs: generated from proto/ with
  python3 -m grpc_tools.protoc ... or protoc --python_out=. --grpc_out=.
      --plugin=protoc-gen-grpc=/usr/bin/grpc_python_plugin fusion/v1/map_service.proto
(the build does this into build/clients/python; set PYTHONPATH to that folder).
"""

import argparse
import math
import os
import sys

import grpc

from fusion.v1 import map_service_pb2 as pb
from fusion.v1 import map_service_pb2_grpc as pb_grpc

BATCH = 4096


def parse_point(text):
    parts = text.split(",")
    if len(parts) != 3:
        raise argparse.ArgumentTypeError(f"'{text}' is not X,Y,Z")
    try:
        values = [float(p) for p in parts]
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not X,Y,Z") from None
    if not all(math.isfinite(v) for v in values):
        raise argparse.ArgumentTypeError(f"'{text}' has a non-finite coordinate")
    return values


def samples(start, goal, step_m, radius_m):
    """Points along the segment, plus 8 around it at radius_m when radius_m > 0."""
    delta = [g - s for s, g in zip(start, goal)]
    length = math.sqrt(sum(d * d for d in delta))
    n = max(1, int(math.ceil(length / step_m)))
    direction = [d / length for d in delta] if length > 0 else [1.0, 0.0, 0.0]
    # Two unit vectors perpendicular to the path.
    helper = [0.0, 0.0, 1.0] if abs(direction[2]) < 0.9 else [1.0, 0.0, 0.0]
    u = cross(direction, helper)
    u = [c / math.sqrt(sum(x * x for x in u)) for c in u]
    v = cross(direction, u)
    offsets = [[0.0, 0.0, 0.0]]
    if radius_m > 0:
        for k in range(8):
            a = 2 * math.pi * k / 8
            offsets.append([radius_m * (math.cos(a) * u[i] + math.sin(a) * v[i]) for i in range(3)])
    for i in range(n + 1):
        t = i / n
        centre = [s + t * d for s, d in zip(start, delta)]
        for off in offsets:
            yield t * length, [c + o for c, o in zip(centre, off)]


def cross(a, b):
    return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]


def check_path(stub, start, goal, radius_m=0.0, unknown_is_obstacle=False, timeout_s=10.0):
    """Returns (clear, blocking_distance_m, blocking_point, counts by state)."""
    stats = stub.GetStats(pb.GetStatsRequest(), timeout=timeout_s)
    step_m = max(stats.resolution_m, 0.01) / 2
    counts = {"occupied": 0, "free": 0, "unknown": 0}
    names = {pb.VOXEL_STATE_OCCUPIED: "occupied", pb.VOXEL_STATE_FREE: "free",
             pb.VOXEL_STATE_UNKNOWN: "unknown"}
    batch = []
    first_block = None

    def flush():
        nonlocal first_block
        request = pb.QueryPointsRequest(points=[pb.Point(x=p[0], y=p[1], z=p[2]) for _, p in batch])
        reply = stub.QueryPoints(request, timeout=timeout_s)
        for (dist, point), result in zip(batch, reply.results):
            state = names.get(result.state, "unknown")
            counts[state] += 1
            blocked = state == "occupied" or (unknown_is_obstacle and state == "unknown")
            if blocked and (first_block is None or dist < first_block[0]):
                first_block = (dist, point)
        batch.clear()

    for item in samples(start, goal, step_m, radius_m):
        batch.append(item)
        if len(batch) == BATCH:
            flush()
    if batch:
        flush()
    if first_block is None:
        return True, None, None, counts
    return False, first_block[0], first_block[1], counts


def read_bytes(path):
    with open(path, "rb") as f:
        return f.read()


def make_channel(args):
    """An insecure channel, or TLS (and a bearer token) when a CA is given."""
    ca = args.tls_ca or os.environ.get("FUSION_TLS_CA")
    cert = args.tls_cert or os.environ.get("FUSION_TLS_CERT")
    key = args.tls_key or os.environ.get("FUSION_TLS_KEY")
    token_file = args.token_file or os.environ.get("FUSION_TOKEN_FILE")
    if not ca:
        if cert or key or token_file:
            raise ValueError("--tls-cert, --tls-key and --token-file need --tls-ca")
        return grpc.insecure_channel(args.server)
    if bool(cert) != bool(key):
        raise ValueError("--tls-cert and --tls-key go together")
    credentials = grpc.ssl_channel_credentials(
        root_certificates=read_bytes(ca),
        private_key=read_bytes(key) if key else None,
        certificate_chain=read_bytes(cert) if cert else None)
    if token_file:
        with open(token_file, encoding="utf-8") as f:
            token = f.readline().strip()
        if not token:
            raise ValueError(f"{token_file}: no token on its first line")
        credentials = grpc.composite_channel_credentials(
            credentials, grpc.access_token_call_credentials(token))
    return grpc.secure_channel(args.server, credentials)


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--server", default="127.0.0.1:50051", help="fusiond address")
    parser.add_argument("--from", dest="start", type=parse_point, required=True, help="X,Y,Z")
    parser.add_argument("--to", dest="goal", type=parse_point, required=True, help="X,Y,Z")
    parser.add_argument("--radius", type=float, default=0.0, help="robot radius in metres")
    parser.add_argument("--unknown-is-obstacle", action="store_true")
    parser.add_argument("--timeout", type=float, default=10.0, help="seconds per call")
    parser.add_argument("--tls-ca", help="CA certificate (PEM) of fusiond's TLS certificate")
    parser.add_argument("--tls-cert", help="client certificate (PEM) for mutual TLS")
    parser.add_argument("--tls-key", help="client key (PEM) for mutual TLS")
    parser.add_argument("--token-file", help="file whose first line is the bearer token")
    args = parser.parse_args(argv)
    if args.radius < 0:
        parser.error("--radius must not be negative")
    try:
        channel = make_channel(args)
    except (OSError, ValueError) as e:
        parser.error(str(e))
    stub = pb_grpc.FusionMapStub(channel)
    try:
        clear, dist, point, counts = check_path(stub, args.start, args.goal, args.radius,
                                                args.unknown_is_obstacle, args.timeout)
    except grpc.RpcError as e:
        print(f"path_check: cannot query fusiond at {args.server}: {e.details()}", file=sys.stderr)
        return 2
    summary = ", ".join(f"{n} {s}" for s, n in counts.items())
    if clear:
        print(f"clear ({summary})")
        return 0
    print(f"blocked at {dist:.3f} m: {point[0]:.3f},{point[1]:.3f},{point[2]:.3f} ({summary})")
    return 1


if __name__ == "__main__":
    sys.exit(main())
