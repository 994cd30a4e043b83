#!/usr/bin/env bash
# Compiler (and linker) launcher that appends "user_s sys_s wall_s output" per command to
# $TIMELOG (default /tmp/crumple-compile-times.txt): where a clean build's CPU time goes.
#   cmake --preset release -B build/timed -DCMAKE_CXX_COMPILER_LAUNCHER=$PWD/scripts/compile_time_log.sh \
#         -DCMAKE_CXX_LINKER_LAUNCHER=$PWD/scripts/compile_time_log.sh -DCRUMPLE_PCH=ON
#   cmake --build build/timed -j2 && sort -rn /tmp/crumple-compile-times.txt | head -20
# (A launcher turns CRUMPLE_PCH off by default, hence -DCRUMPLE_PCH=ON to time the CI build.)
out=""
prev=""
for a in "$@"; do
  [ "$prev" = "-o" ] && out="$a"
  prev="$a"
done
log=${TIMELOG:-/tmp/crumple-compile-times.txt}
/usr/bin/time -o "$log.$$" -f "%U %S %e" "$@"
rc=$?
echo "$(tail -n 1 "$log.$$") $out" >> "$log"
rm -f "$log.$$"
exit $rc
