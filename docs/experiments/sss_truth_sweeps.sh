#!/bin/bash
# The README's translucency sweeps: relative RMSE against the volumetric truth and render time
# for each profile model and option of sss.render, marble and skin1 on graphs/sss_truth.json's
# torus. `mesoflow sweep` runs every sink of a graph, so each material is swept on a copy of
# the graph holding only its own nodes (the other material's render and the brute-force gather
# would otherwise share the cores with the first run's timing and rerun with each profile).
# The truths come from the cache (`--cache-dir`, default the graph's): run
# `mesoflow run graphs/sss_truth.json` once first. Usage:
#   docs/experiments/sss_truth_sweeps.sh [OUT_DIR] [CACHE_DIR]
# SWEEPS="sources single" runs only those (default: sources shape single emission), and
# MATERIALS="skin1" only that material (default: marble skin1).
set -euo pipefail
cd "$(dirname "$0")/../.."
out=${1:-out/sss_truth-sweeps}
cache=${2:-graphs/.mesoflow/cache}
bin=${MESOFLOW:-target/release/mesoflow}
mkdir -p "$out"
for m in ${MATERIALS:-marble skin1}; do
  python3 - "$m" "$out/${m}_only.json" <<'PY'
import json, sys
m, path = sys.argv[1:]
g = json.load(open("graphs/sss_truth.json"))
keep = {"torus", f"{m}_material", f"{m}_truth", f"{m}_profile", m, f"{m}_error"}
g["nodes"] = {k: v for k, v in g["nodes"].items() if k in keep}
g["description"] = f"graphs/sss_truth.json's {m} nodes alone, for the README's sweeps"
json.dump(g, open(path, "w"), indent=2)
PY
  sweep() {
    local name=$1; shift
    [[ " ${SWEEPS:-sources shape single emission} " == *" $name "* ]] || return 0
    "$bin" sweep "$out/${m}_only.json" --cache-dir "$cache" -q --device cpu \
      --vary "${m}_profile.model=dipole,better_dipole,pbd,pbd_multiple" "$@" \
      --measure "${m}_error.relative_rmse" --measure "${m}_error.bias" --measure "$m.seconds" \
      --versus "$m.seconds" --out-dir "$out/${m}_$name"
  }
  # Where the light starts to diffuse, and the object's shape (the two geometries the beam needs).
  sweep sources --vary "$m.sources=point,beam" --vary "$m.geometry=exit_normal,body"
  # The shape with Jensen's sources, every geometry, with and without light between parts.
  sweep shape --set "$m.sources=point" --vary "$m.geometry=planar,exit_normal,body,directional" \
    --vary "$m.bounces=0,2"
  # Single scattering.
  sweep single --vary "$m.single_scattering=false,true" \
    --vary "$m.single_scattering_shape=half_space,traced"
  # The exit's angular shape.
  sweep emission --vary "$m.emission=diffuse,p1,half_space"
done
