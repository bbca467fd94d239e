"""Vector-env benchmarks: throughput (and its modules), peers, multi-node, chaos, ray_ports."""
