#!/usr/bin/env bash
# Run a command while one CPU-burning process per core keeps the machine busy, as a
# teleoperation computer is; the burners end with the command. Usage: busy.sh COMMAND...
set -euo pipefail
pids=()
for _ in $(seq "$(nproc)"); do
  python3 -c "while True: pass" &
  pids+=("$!")
done
trap 'kill "${pids[@]}" 2>/dev/null || true' EXIT
echo "[busy] $(nproc) burners running: ${pids[*]}"
"$@"
