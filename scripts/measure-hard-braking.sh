#!/usr/bin/env bash
# Figures for docs/control.md ("Answer to a hard-braking lead"): how soon the ACC answers a
# lead that brakes, across its deceleration (2.5 to 4.5 m/s2, either side of the 3.5 m/s2
# comfort limit), its speed (15, 25, 32 m/s, followed at the 1.8 s gap) and its class (car,
# truck, motorcycle), with each perception. Writes the 63 scenarios to a directory of its own,
# runs `slipstream eval acc` on them (lockstep: deterministic) and prints, per perception,
# a table of the answer (s; "-" where the lead never braked beyond the comfort limit) and the
# emergency seconds (in brackets: the unwarranted emergencies). About 2 minutes on 2 cores. Needs a release build.
# SEED_OFFSET=N adds N to every scenario's seed (the same sweep with other noise).
set -euo pipefail
cd "$(dirname "$0")/.."
bin=target/release/slipstream
out=${1:-target/measure-hard-braking}
rm -rf "$out" && mkdir -p "$out/scenarios"

classes=(car truck motorcycle)
speeds=(15 25 32)
decels=(2.5 3.0 3.3 3.5 3.7 4.0 4.5)
args=()
for class in "${classes[@]}"; do
  for v in "${speeds[@]}"; do
    for d in "${decels[@]}"; do
      name="brake-$class-$v-$d"
      # Motorcycles ride off their lane's centre; the lead slows by 12 m/s (to 2 m/s at least).
      offset=0.0; [ "$class" = motorcycle ] && offset=0.9
      to=$((v > 14 ? v - 12 : 2))
      gap=$(python3 -c "print(round(1.8 * $v + 5))")
      cat >"$out/scenarios/$name.json5" <<EOF
{
  name: "$name",
  description: "A $class at $v m/s, 1.8 s ahead, brakes at $d m/s2 to $to m/s at t = 12 s.",
  duration_s: 22,
  seed: $((v * 10 + ${d%.*} + ${SEED_OFFSET:-0})),
  ego: { lane: 1, speed_mps: $v, set_speed_mps: $((v + 3)), time_gap_s: 1.8 },
  traffic: [
    {
      lane: 1, offset_m: $offset, gap_m: $gap, speed_mps: $v, class: "$class",
      actions: [ { at_s: 12, speed_mps: $to, accel_mps2: $d } ],
    },
  ],
}
EOF
      args+=(--scenario "$out/scenarios/$name.json5")
    done
  done
done

for perception in ${PERCEPTIONS:-camera ground-truth}; do
  "$bin" eval acc --perception "$perception" "${args[@]}" --logs "$out/logs-$perception" >"$out/$perception.md" 2>&1 || true
  echo
  echo "== $perception: answer s / emergency s (unwarranted), by the lead's deceleration"
  python3 - "$out/$perception.md" "${decels[*]}" <<'EOF'
import sys
rows = {}
for line in open(sys.argv[1]):
    cells = [c.strip() for c in line.split("|")[1:-1]]
    if len(cells) > 13 and cells[0].startswith("brake-"):
        _, cls, v, d = cells[0].split("-")
        rows[(cls, v, d)] = (cells[11], cells[12], cells[-1])
decels = sys.argv[2].split()
print("| lead | " + " | ".join(f"{d} m/s2" for d in decels) + " |")
print("|---" * (len(decels) + 1) + "|")
for cls in ("car", "truck", "motorcycle"):
    for v in ("15", "25", "32"):
        cells = []
        for d in decels:
            answer, emergency, result = rows.get((cls, v, d), ("?", "?", "?"))
            cell = f"{answer} / {emergency}"
            cells.append(cell if result == "pass" else cell + " FAIL")
        print(f"| {cls} {v} m/s | " + " | ".join(cells) + " |")
EOF
done
