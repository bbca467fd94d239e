#!/usr/bin/env bash
# Scale-out on a machine with many cores, in one run of about 6 minutes on 16 cores: the
# synthetic sweep to W = 64 (scaling.py), a short one with Ant-v5's nine scalar infos per step
# (scaling_infos), the machine's ceiling (ceiling.py), the real workloads against EnvPool's
# threads with the synthetic model's prediction beside them (cores.py), and forked workers,
# Ray workers and AsyncVectorEnv side by side with a core per worker (side_by_side.py: do Ray
# workers' idle wake-ups still cost them steps when no worker shares a core?). Every JSON and
# log lands in OUT_DIR, and the PNGs of scaling and cores.
#
#     bash benchmarks/vector/many_cores.sh OUT_DIR          # the full run
#     QUICK=1 bash benchmarks/vector/many_cores.sh OUT_DIR  # smoke run, about 1 min
#
# Run from the repository's root with chronogym importable (installed, or PYTHONPATH=src; on a
# machine with no network, see benchmarks/offline_kit.py). Where Ray is not importable, the
# paths that need it (socket) are left out and the rest run: forked workers, AsyncVectorEnv,
# EnvPool. Nothing else should run meanwhile.
set -euo pipefail
out=${1:?usage: many_cores.sh OUT_DIR}
mkdir -p "$out"
python=${PYTHON:-python3}
export PYTHONUNBUFFERED=1
cpus=$("$python" -c "import os; print(os.cpu_count())")
if "$python" -c "import ray" 2>/dev/null; then ray_paths=(socket); else ray_paths=(); fi
echo "many_cores: $cpus CPUs; Ray paths: ${ray_paths[*]:-none (Ray is not importable)}"

if [[ ${QUICK:-0} == 1 ]]; then
    workers=(1 2 8); cores_workers=(1 2); epw=(1 2); step_ms=(1); seconds=0.3
    side=(--workers 2 --rounds 1 --steps 50)
else
    workers=(1 2 4 8 16 32 64); cores_workers=(1 2 4 8 $((cpus - 1))); epw=(1 8)
    step_ms=(1 10); seconds=1
    side=(--workers 1 "$((cpus > 2 ? cpus - 1 : 1))" --rounds 3 --steps 500)
fi

status=0
run() {  # run() NAME ARGS...: one benchmark, its log beside its JSON; a failure does not stop
    local name=$1 script=${1%_infos}
    shift
    "$python" -m "benchmarks.vector.$script" "$@" --out "$out/$name.json" 2>&1 |
        tee "$out/$name.log" || status=1
}

run scaling --paths fork async "${ray_paths[@]}" \
    --straggler-paths fork "${ray_paths[@]}" --straggler-workers "$((cpus < 16 ? cpus : 16))" \
    --workers "${workers[@]}" --envs-per-worker "${epw[@]}" --step-ms "${step_ms[@]}" \
    --seconds "$seconds"
run scaling_infos --paths fork async "${ray_paths[@]}" --no-stragglers --info-scalars 9 \
    --workers "${workers[@]}" --envs-per-worker 1 --step-ms 1 --seconds "$seconds"
run ceiling --paths fork async "${ray_paths[@]}" \
    --workers "${workers[@]}" --step-ms "${step_ms[@]}" --seconds "$seconds"
run cores --paths fork async envpool "${ray_paths[@]}" \
    --workers "${cores_workers[@]}" --envs-per-worker "${epw[@]}" --seconds "$seconds" \
    --model "$out/scaling.json" "$out/scaling_infos.json"
run side_by_side --env chronogym/Synthetic-v0 --env-kwargs '{"step_ms": 1.0, "info_scalars": 9}' \
    --kinds fork "${ray_paths[@]}" async "${side[@]}" --idle-s 1
exit $status
