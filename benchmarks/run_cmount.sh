#!/usr/bin/env bash
# The C-mount study (seed S6.1, issue 3): lensopt optimize from the crude start of specs/cmount_4p.toml.
# Records the load, the wall time and the summary (ESR, constraint values, glasses) under out/.
#
#   benchmarks/run_cmount.sh            # OMP_NUM_THREADS and nice level can be overridden
set -euo pipefail
cd "$(dirname "$0")/.."
mkdir -p out
THREADS="${OMP_NUM_THREADS:-1}"
NICE="${NICE:-3}"
echo "load before: $(cat /proc/loadavg)" | tee out/cmount_4p_run.txt
start=$(date +%s.%N)
OMP_NUM_THREADS="$THREADS" nice -n "$NICE" .venv/bin/lensopt optimize specs/cmount_4p.toml \
    -o out/cmount_4p.json --seed 0 --quiet --json > out/cmount_4p_summary.json
end=$(date +%s.%N)
echo "load after: $(cat /proc/loadavg)" | tee -a out/cmount_4p_run.txt
echo "wall seconds: $(echo "$end - $start" | bc)  (threads $THREADS, nice $NICE)" | tee -a out/cmount_4p_run.txt
.venv/bin/python - <<'PY' | tee -a out/cmount_4p_run.txt
import json
s = json.load(open("out/cmount_4p_summary.json"))
c = s["constraints"]
print(f"steps {s['steps']} ({s['stop_reason']}), optimizer time {s['elapsed_s']:.0f} s")
print(f"ESR (rings:24) {s['start']['effective_spot_radius_um']:.2f} -> {s['final']['effective_spot_radius_um']:.3f} um")
fo = s["final"]["first_order"]
print(f"EFL {fo['efl']:.6f} mm, f/{fo['fnumber']:.4f}, TTL {fo['total_track']:.3f} mm")
for g in c.get("gaps", []):
    print(f"  gap {g['gap']} {g['kind']}: centre {g['centre']:.3f}, t_z {g['min']:.3f}..{g['max']:.3f}, "
          f"bounds [{g['lower']:.3f}, {g['upper']}] ok={g['satisfied']}")
print(f"max angle {c['max_angle_deg']:.2f} deg, max |distortion| {max(abs(v) for v in c['distortion_percent']):.3f} %")
print("glasses:", ", ".join(m["material"] for m in c["materials"]))
print("constraints satisfied:", c["satisfied"], "| warning:", s["warning"] or "none")
PY
.venv/bin/lensopt trace out/cmount_4p.json > out/cmount_4p_trace.txt
