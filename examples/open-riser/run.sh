#!/usr/bin/env bash
# Make the dump of the open-riser example: 3 s of simulated time, one file per 0.01 s in out/
# (about 30 s on one core). LAMMPS is found as cfbmarkov finds it (CFBMARKOV_LAMMPS, next to
# the Python executable, or on PATH); extra arguments go to LAMMPS (e.g. -var steps 20000).
set -euo pipefail
here="$(cd "$(dirname "$0")" && pwd)"
python="${PYTHON:-python}"
if [ -z "${LMP:-}" ] && ! "$python" -c 'import cfbmarkov.simulate.dem.lammps' 2>/dev/null; then
    echo "$python cannot import cfbmarkov: set PYTHON to the interpreter it is installed in" \
         "(e.g. PYTHON=.venv/bin/python), or LMP to the LAMMPS executable" >&2
    exit 1
fi
lmp="${LMP:-$("$python" -c 'from cfbmarkov.simulate.dem.lammps import find_lammps; print(find_lammps() or "")')}"
if [ -z "$lmp" ]; then
    echo "no LAMMPS executable found (set LMP or CFBMARKOV_LAMMPS)" >&2
    exit 1
fi
cd "$here"
rm -rf out
mkdir -p out
export OMP_NUM_THREADS=1
time "$lmp" -in riser.in -log out/log.lammps -screen none "$@"
grep -A1 '^Loop time' out/log.lammps | head -1
