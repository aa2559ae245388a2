#!/usr/bin/env bash
# The scripts' own arguments (test simdvol_scripts_arguments): --help prints
# the script's header and does nothing else; an argument a script does not
# take is refused with exit 2, naming it, before it installs, downloads or
# builds anything. Also bench-ab's summary on stand-ins for the binaries it
# compares. Runs in well under a second.
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
fail=0
check() {  # check <want rc> <text the output must hold> <command...>
  local want=$1 text=$2
  shift 2
  local out rc
  out=$("$@" 2>&1 </dev/null)
  rc=$?
  if [ "$rc" -ne "$want" ] || [[ "$out" != *"$text"* ]]; then
    echo "FAIL: $* -> rc $rc (want $want), output lacks '$text':" >&2
    printf '%s\n' "$out" | head -n 5 >&2
    fail=1
  fi
}
for s in fetch-data install-deps install-peers check-format test embed-check; do
  check 2 "$s: takes no arguments, not '--bogus'" "$root/scripts/$s" --bogus
  check 0 "$(sed -n '2s/^# //p' "$root/scripts/$s")" "$root/scripts/$s" --help
done
# scripts/test's help names every step it runs and the variables it takes
# (it left out embed-check and the ASan build's switches).
for t in scripts/embed-check "ASan + UBSan" SIMDVOL_SKIP_SANITIZE SIMDVOL_ASAN_BUILD_DIR SIMDVOL_JOBS; do
  check 0 "$t" "$root/scripts/test" --help
done
check 2 "'--target' is a build-step option" "$root/scripts/build" --target simdvol
check 0 "Configures and builds simdvol" "$root/scripts/build" --help
# A CC or CXX that is not the compiler an existing build directory has is
# refused before CMake runs (CMake ignored it and built with the old one).
# A stand-in cmake on PATH fails at once should the script get that far.
cached=$(mktemp -d)
printf 'CMAKE_C_COMPILER:FILEPATH=/usr/bin/cc\nCMAKE_CXX_COMPILER:FILEPATH=/usr/bin/c++\n' \
  >"$cached/CMakeCache.txt"
mkdir "$cached/bin"
printf '#!/bin/sh\necho "cmake ran"\nexit 1\n' >"$cached/bin/cmake"
chmod +x "$cached/bin/cmake"
check 2 "$cached was configured with /usr/bin/c++, not CXX=/bin/true" \
  env PATH="$cached/bin:$PATH" CXX=/bin/true SIMDVOL_BUILD_DIR="$cached" "$root/scripts/build"
check 2 "$cached was configured with /usr/bin/cc, not CC=/bin/true" \
  env PATH="$cached/bin:$PATH" CC=/bin/true SIMDVOL_BUILD_DIR="$cached" "$root/scripts/build"
rm -rf "$cached"
check 0 "scripts/demo [render options]" "$root/scripts/demo" -h
check 0 "scripts/reproduce [--no-build]" "$root/scripts/reproduce" --help
check 2 "unknown argument '--bogus'" "$root/scripts/reproduce" --bogus
check 2 "fuzz: unknown argument '--bogus'" "$root/scripts/fuzz" --bogus
check 0 "$(sed -n '2s/^# //p' "$root/scripts/bench-ab")" "$root/scripts/bench-ab" --help
check 2 "bench-ab: need two simdvol-bench-options binaries" "$root/scripts/bench-ab"
check 2 "bench-ab: --bogus: unknown argument" "$root/scripts/bench-ab" /bin/true /bin/true --bogus
# bench-ab on stand-ins for simdvol-bench-options that print its table: a
# column that is 0.00 in every run of A has no ratio (it printed -nan, exit
# 0); a column the output lacks is an error.
stubs=$(mktemp -d)
trap 'rm -rf "$stubs"' EXIT
stub() {  # stub <file> <header> <row>
  printf '#!/usr/bin/env bash\necho "%s"\necho "%s"\n' "$2" "$3" >"$1"
  chmod +x "$1"
}
stub "$stubs/zero" "variant shcls match bal rs+loc swap wall" "(none) 1.00 2.00 0.00 4.00 5.00 6.00"
stub "$stubs/nobal" "variant shcls match rs+loc swap wall" "(none) 1.00 2.00 4.00 5.00 6.00"
check 0 "bal: median A 0.00 ms, B 0.00 ms; median B / A undefined: A's bal is 0.00 ms in every pair" \
  "$root/scripts/bench-ab" "$stubs/zero" "$stubs/zero" --pairs 2 --column bal
check 0 "rs+loc: median A 4.00 ms, B 4.00 ms; median B / A over 2 pairs 1.000" \
  "$root/scripts/bench-ab" "$stubs/zero" "$stubs/zero" --pairs 2
check 1 "bench-ab: $stubs/nobal: no 'bal' figure in its output" \
  "$root/scripts/bench-ab" "$stubs/zero" "$stubs/nobal" --pairs 2 --column bal
# scripts/reproduce's reading of fig 7 (fig7_reading.sh) from a CSV of the
# figures in bench/REPRODUCTION.md: where a curve passes 38 dB is read from
# them (a fixed text said the phantom's whole plain stays below 38 dB at
# n = 128 beside a row that reads 38.05 there).
fig7_csv() {  # fig7_csv <phantom whole plain shared at n = 128>
  echo "dataset,scope,variant,streams,n,psnr_db,walks_per_ray,draws_per_ray,fallbacks"
  local d v n i
  local -A row=(
    [ct-phantom-256,whole,plain,per-ray]="15.73 18.68 21.76 24.76 27.75 30.78 33.73 36.80"
    [ct-phantom-256,whole,plain,shared]="16.16 19.24 22.61 24.85 27.85 30.83 33.83 $1"
    [ct-phantom-256,sub,strat,per-ray]="26.80 31.17 37.17 42.59 48.57 54.59 60.89 67.02"
    [brainsmall,whole,plain,per-ray]="24.18 27.30 30.55 33.45 36.63 39.57 42.77 45.56"
    [brainsmall,whole,plain,shared]="23.01 27.73 30.56 33.39 35.92 39.27 42.45 46.24"
    [brainsmall,sub,strat,per-ray]="31.17 36.52 41.65 47.34 52.77 58.45 64.38 70.30")
  for d in "${!row[@]}"; do
    i=0
    for v in ${row[$d]}; do
      n=$((1 << i++))
      echo "$d,$n,$v,8,8,0"
    done
  done
}
reading() {  # reading <csv text>: the paragraphs on one line
  (. "$root/scripts/fig7_reading.sh" && fig7_reading <(printf '%s\n' "$1")) | tr '\n' ' '
}
check 0 "it passes 38 dB only at n = 128 with shared streams (38.05 dB) and stays below it with per-ray ones (36.80 dB at n = 128)" \
  reading "$(fig7_csv 38.05)"
check 0 "it stays below 38 dB even at n = 128 (36.80 dB with per-ray streams, 37.40 dB with shared ones)" \
  reading "$(fig7_csv 37.4)"
check 0 "passes the thesis's 38 dB \"visibly identical\" line at n = 32, the thesis's threshold" \
  reading "$(fig7_csv 38.05)"
check 0 "it passes 38 dB at n = 8 walks per sub-ray on the phantom and at n = 4 on brainsmall," \
  reading "$(fig7_csv 38.05)"
# help ends before the script's code
if "$root/scripts/reproduce" --help | grep -q 'set -euo'; then
  echo "FAIL: scripts/reproduce --help prints its code" >&2
  fail=1
fi
exit $fail
