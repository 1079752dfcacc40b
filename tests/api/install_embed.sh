#!/usr/bin/env bash
# Installs the build into a fresh prefix and builds examples/embed against
# it (find_package(Tissue CONFIG) with nothing but the prefix), then runs it
# on the kidney and checks that the tool felt a force; then a host linking
# every exported target (tests/api/install_targets) configures, links and runs.
# Usage: install_embed.sh BUILD_DIR EMBED_SOURCE WORK_DIR
set -euo pipefail
build=$1 src=$2 work=$3
rm -rf "$work"
cmake --install "$build" --prefix "$work/prefix" > "$work.install.log" 2>&1 || { cat "$work.install.log"; exit 1; }
test -f "$work/prefix/include/tissue/simulation.hpp"
test -f "$work/prefix/include/tissue/tissue_c.h"
ls "$work/prefix"/lib*/cmake/Tissue/TissueConfig.cmake "$work/prefix"/lib*/cmake/Tissue/TissueConfigVersion.cmake
cmake -S "$src" -B "$work/embed" -DCMAKE_PREFIX_PATH="$work/prefix" -DCMAKE_BUILD_TYPE=Release
cmake --build "$work/embed"
# The host runs from the install tree alone: the build tree moved out of reach.
out=$("$work/embed/embed" @kidney cpu)
echo "$out"
grep -q "nodes, .* tets on cpu" <<< "$out"
# every exported target, linked by a host of its own (tests/api/install_targets)
cmake -S "$(dirname "$0")/install_targets" -B "$work/targets" -DCMAKE_PREFIX_PATH="$work/prefix" \
  -DCMAKE_BUILD_TYPE=Release > "$work.targets.log" 2>&1 || { cat "$work.targets.log"; exit 1; }
cmake --build "$work/targets" >> "$work.targets.log" 2>&1 || { cat "$work.targets.log"; exit 1; }
"$work/targets/every_target" | tee -a "$work.targets.log" | grep -q "nodes, tick 0"
# the Python package from the prefix alone (when it was built): its module
# finds libtissue in the prefix's lib
site=$(ls -d "$work/prefix"/lib*/python3*/dist-packages 2>/dev/null | head -1 || true)
if [ -n "$site" ] && [ -f "$site/tissue/__init__.py" ]; then
  py=/usr/bin/python3
  [ -x "$py" ] || py=python3
  PYTHONPATH="$site" "$py" -c "import tissue, sys; assert tissue.__file__.startswith('$work/prefix'), tissue.__file__; s = tissue.Simulation.load('@kidney', backend='cpu'); s.step(5); print('python from the prefix:', tissue.__file__, s)"
fi
# the last line's vertical force: the tool pushed into the kidney feels it push back up
fz=$(tail -1 <<< "$out" | sed -E 's/.*force \([^,]+, [^,]+, ([^)]+)\) N.*/\1/')
awk -v f="$fz" 'BEGIN { exit !(f > 0.001) }' || { echo "vertical force $fz N is not > 0.001 N"; exit 1; }
