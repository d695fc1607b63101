#!/usr/bin/env bash
# The cost of running on Slurm, on the local two-node cluster of scripts/slurm-local:
#  1. overhead per unit: 16 independent units that do nothing (scalar.constant → scalar.affine),
#     wall time of `mesoflow run --engine slurm` divided by the units, on w1 and w2;
#  2. the 8-variant sweep of tests/slurm.rs (graphs/btf_compress.json at 32², pca.rank=1…8) on one
#     worker (w2 drained) and on two, against the same sweep run locally.
# Run: eval "$(scripts/slurm-local start)"; bash benches/cluster.sh
set -euo pipefail
cd "$(dirname "$0")/.."
exe="$PWD/target/release/mesoflow"
tmp="$(mktemp -d)"
export MESOFLOW_SLURM_POLL_MS=200
secs() { local t0 t1; t0=$(date +%s.%N); "$@" >/dev/null; t1=$(date +%s.%N); echo "$t1 - $t0" | bc; }

python3 - "$tmp/units.json" <<'PY'
import json, sys
nodes = {}
for i in range(16):
    nodes[f"c{i}"] = {"kind": "scalar.constant", "params": {"value": i}}
    nodes[f"a{i}"] = {"kind": "scalar.affine", "inputs": {"x": f"c{i}.value"}, "params": {"scale": 2}}
json.dump({"mesoflow": 1, "nodes": nodes}, open(sys.argv[1], "w"))
PY
t=$(secs "$exe" run "$tmp/units.json" --quiet --engine slurm --cache-dir "$tmp/c1" --out-dir "$tmp/o1")
echo "16 empty units on w1+w2: $t s, $(echo "scale=2; $t / 16" | bc) s per unit"

sweep() {
    "$exe" sweep graphs/btf_compress.json --quiet --set surface.size=32 --vary pca.rank=1,2,3,4,5,6,7,8 \
        --measure pca.rmse --measure compare.rmse "$@"
}
t=$(secs sweep --out-dir "$tmp/local" --cache-dir "$tmp/local-cache")
echo "8-variant sweep, local: $t s"
t=$(secs sweep --engine slurm --out-dir "$tmp/two" --cache-dir "$tmp/two-cache")
echo "8-variant sweep, w1+w2: $t s ($(ls "$tmp/two/cluster/units/"*.job | wc -l) units)"
scontrol update nodename=w2 state=drain reason=benchmark
t=$(secs sweep --engine slurm --out-dir "$tmp/one" --cache-dir "$tmp/one-cache")
scontrol update nodename=w2 state=resume
echo "8-variant sweep, w1 alone: $t s"
rm -rf "$tmp"
