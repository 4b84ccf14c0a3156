#!/usr/bin/env bash
# Measures what sharding buys on the local Slurm cluster (.ci/slurm-up, two
# CPU slots): six built-in subjects trained by one process, then by a
# two-task array of one CPU each. Prints the wall times and the speed-up.
#
#   deploy/slurm/bench-array.sh [VISAGE_BINARY] [ITERATIONS] [SIZE]
set -euo pipefail
here="$(cd "$(dirname "$0")/../.." && pwd)"
visage="$(realpath "${1:-$here/target/release/visage}")"
iterations="${2:-600}"
size="${3:-64x64}"
export SLURM_CONF="$("$here/.ci/slurm-up")" NODEVICE_SELECT=1
work="$(mktemp -d)"
cd "$work"
mkdir -p logs
write_manifest() { # output
  printf 'output = "%s"\n[defaults]\niterations = %s\nsize = "%s"\nrenderer = "cpu"\n' "$1" "$iterations" "$size"
  for p in ada bram cleo dries elif femi; do
    printf '[[subject]]\nid = "%s"\ndataset = "captures/%s"\n[subject.capture]\nsource = "%s"\nsize = "128x128"\ncameras = 8\nframes = 4\n' "$p" "$p" "$p"
  done
}
write_manifest single >single.toml
write_manifest array >array.toml
"$visage" capture --manifest single.toml 2>/dev/null
seconds() { awk -v a="$1" -v b="$2" 'BEGIN { printf "%.1f", b - a }'; }
for threads in 1 2; do
  rm -rf single
  start=$(date +%s.%N)
  RAYON_NUM_THREADS=$threads "$visage" train --manifest single.toml 2>/dev/null
  took=$(seconds "$start" "$(date +%s.%N)")
  echo "one process, $threads thread(s): $took s"
  eval "single_$threads=$took"
done
start=$(date +%s.%N)
job=$(sbatch --parsable --array=0-1 --export=ALL,VISAGE="$visage" "$here/deploy/slurm/visage-array.sbatch" array.toml)
# Polled here: sbatch --wait checks less and less often.
while [ -n "$(squeue -h -j "$job" -o %i)" ]; do sleep 0.2; done
array=$(seconds "$start" "$(date +%s.%N)")
echo "Slurm array of 2 one-CPU tasks: $array s (submission to the end of the last task)"
grep -h "trained in" logs/* | sed 's/^/  /'
awk -v s1="$single_1" -v s2="$single_2" -v a="$array" \
  'BEGIN { printf "speed-up over one process: %.2fx (1 thread), %.2fx (2 threads)\n", s1 / a, s2 / a }' 
for p in ada bram cleo dries elif femi; do
  for f in point_cloud.ply flame_param.npz training.json subject.json; do
    cmp -s "single/$p/$f" "array/$p/$f" || { echo "bench-array: $p/$f differs between the runs" >&2; exit 1; }
  done
done
echo "all six avatars are byte-identical between the runs"
rm -rf "$work"
