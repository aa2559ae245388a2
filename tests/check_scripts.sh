#!/usr/bin/env bash
# The scripts' own arguments (test simdvol_scripts_arguments): --help prints
# the script's header and does nothing else; an argument a script does not
# take is refused with exit 2, naming it, before it installs, downloads or
# builds anything. Runs in well under a second.
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
check 2 "'--target' is a build-step option" "$root/scripts/build" --target simdvol
check 0 "Configures and builds simdvol" "$root/scripts/build" --help
check 0 "scripts/demo [render options]" "$root/scripts/demo" -h
check 0 "scripts/reproduce [--no-build]" "$root/scripts/reproduce" --help
check 2 "unknown argument '--bogus'" "$root/scripts/reproduce" --bogus
check 2 "fuzz: unknown argument '--bogus'" "$root/scripts/fuzz" --bogus
# help ends before the script's code
if "$root/scripts/reproduce" --help | grep -q 'set -euo'; then
  echo "FAIL: scripts/reproduce --help prints its code" >&2
  fail=1
fi
exit $fail
