#!/usr/bin/env bash
# Run a command while CPU-burning processes keep the machine busy, as a teleoperation
# computer is; the burners end with the command.
# Usage: busy.sh [-n BURNERS] COMMAND...   (default: one burner per core)
set -euo pipefail
count="$(nproc)"
if [ "${1:-}" = "-n" ]; then
  count="$2"
  shift 2
fi
pids=()
for _ in $(seq "$count"); do
  python3 -c "while True: pass" &
  pids+=("$!")
done
trap 'kill "${pids[@]}" 2>/dev/null || true' EXIT
echo "[busy] $count burners on $(nproc) cores: ${pids[*]}"
"$@"
