#!/usr/bin/env bash
# The docs against the code (test simdvol_docs_against_code), where a
# machine can tell:
# - README.md's dependency table names exactly the packages
#   scripts/install-deps installs, and its optional table exactly those of
#   scripts/install-peers (it listed libbenchmark-dev, which nothing uses,
#   and not libvolpack1-dev);
# - every option of `simdvol render --help` is named in README.md, and every
#   option in the first column of README.md's `render` option table is one
#   that --help lists;
# - every SIMDVOL_ environment variable host/ reads is named in README.md
#   (SIMDVOL_VOXEL_WGS and the DICOM and MINC in-process switches were not);
# - README.md names every public header (its list of the headers named 13 of the 27),
#   and simdvol.hpp, which README says includes them all, does;
# - every stage function docs/KERNELS.md names (enqueue_*, upload_*, make_*,
#   read_*, set_resample_view) is declared in the public headers.
#   check_docs.sh SIMDVOL    (the built simdvol program)
set -uo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
simdvol=${1:?usage: check_docs.sh SIMDVOL}
fail=0
bad() {
  echo "FAIL: $*" >&2
  fail=1
}

# The packages of a script's pkgs=( ... ) array, one a line, sorted.
script_pkgs() {
  sed -n '/^pkgs=(/,/^)/p' "$1" | sed '1d;$d' | sed 's/#.*//' | tr -s ' \t' '\n' | sed '/^$/d' |
    sort -u
}
# The packages in the first column of the table under README.md's heading
# $1, up to the next heading or (with $2) the line holding $2.
readme_pkgs() {
  sed 's/\\|/ /g' "$root/README.md" | awk -F'|' -v head="$1" -v stop="${2:-}" '
    index($0, head) == 1 { on = 1; next }
    on && /^#/ { exit }
    on && stop != "" && index($0, stop) { exit }
    on && /^\| `/ { print $2 }' |
    grep -o '`[^`]*`' | tr -d '`' | sort -u
}
deps_readme=$(readme_pkgs "## Dependencies" "Optional, for the VTK peer")
deps_script=$(script_pkgs "$root/scripts/install-deps")
if [ "$deps_readme" != "$deps_script" ]; then
  bad "README.md's dependency table and scripts/install-deps differ (< README, > install-deps):"
  diff <(echo "$deps_readme") <(echo "$deps_script") | grep '^[<>]' >&2
fi
[ -n "$deps_script" ] || bad "no packages read from scripts/install-deps"
peers_readme=$(sed 's/\\|/ /g' "$root/README.md" | awk -F'|' '/^Optional, for the VTK peer/ { on = 1; next } on && /^\| `/ { print $2 }
                    on && /^$/ && seen { exit } on && /^\|/ { seen = 1 }' |
  grep -o '`[^`]*`' | tr -d '`' | sort -u)
peers_script=$(script_pkgs "$root/scripts/install-peers")
if [ "$peers_readme" != "$peers_script" ]; then
  bad "README.md's optional table and scripts/install-peers differ (< README, > install-peers):"
  diff <(echo "$peers_readme") <(echo "$peers_script") | grep '^[<>]' >&2
fi

help=$("$simdvol" render --help) || bad "$simdvol render --help failed"
help_opts=$(printf '%s\n' "$help" | grep -oE '^ +(-[a-z],)?--[a-z0-9-]+' | sed 's/.*--/--/' |
  grep -vx -- '--help\|--output' | sort -u)
[ -n "$help_opts" ] || bad "no options read from render --help"
for o in $help_opts; do
  # the whole name: `--pe` is not named by `--pes`
  grep -qE -- "\`$o([^a-z0-9-]|\$)" "$root/README.md" || bad "README.md does not name render's $o"
done
table_opts=$(sed 's/\\|/ /g' "$root/README.md" | awk -F'|' '/^`render` options/ { on = 1; next } on && /^\| `/ { print $2 }
                  on && /^$/ && seen { exit } on && /^\|/ { seen = 1 }' |
  grep -oE -- '--[a-z0-9-]+' | sort -u)
[ -n "$table_opts" ] || bad "no options read from README.md's render option table"
# A here-string, not printf | grep -q: grep -q exits at its first match,
# and under pipefail a printf still writing then dies of SIGPIPE (141) and
# the pipeline fails: now and then an option that --help lists was reported
# missing (`--depth-cue`, 3 of 50 runs two at a time on a loaded machine).
for o in $table_opts; do
  grep -qx -- "$o" <<<"$help_opts" || bad "README.md's render table names $o, which render --help does not list"
done

# Every environment variable the library and the program read.
envs=$(grep -rhoE '(getenv|env_switch)\("SIMDVOL_[A-Z_]+"' "$root/host" | grep -oE 'SIMDVOL_[A-Z_]+' |
  sort -u)
[ -n "$envs" ] || bad "no SIMDVOL_ variables read from host/"
for e in $envs; do
  grep -q "\b$e\b" "$root/README.md" || bad "README.md does not name $e, which host/ reads"
done

for h in "$root"/host/include/simdvol/*.hpp; do
  grep -q "\`$(basename "$h")\`" "$root/README.md" || bad "README.md does not name the public header $(basename "$h")"
done
# README.md says simdvol.hpp includes them all (it left out costmodel.hpp).
for h in "$root"/host/include/simdvol/*.hpp; do
  b=$(basename "$h")
  [ "$b" = simdvol.hpp ] || grep -q "^#include \"simdvol/$b\"" "$root/host/include/simdvol/simdvol.hpp" ||
    bad "host/include/simdvol/simdvol.hpp does not include the public header $b"
done

funcs=$(grep -oE '\b(enqueue|upload|make|read)_[a-z0-9_]+\(|\bset_resample_view\b' \
  "$root/docs/KERNELS.md" | tr -d '(' | sort -u)
[ -n "$funcs" ] || bad "no functions read from docs/KERNELS.md"
for f in $funcs; do
  grep -qE "\b$f\(" "$root"/host/include/simdvol/*.hpp ||
    bad "docs/KERNELS.md names $f(...), which no public header declares"
done

[ "$fail" -eq 0 ] && echo "docs against the code: ok ($(echo "$deps_script" | wc -l) dependencies, $(echo "$help_opts" | wc -l) render options, $(echo "$envs" | wc -l) variables, $(echo "$funcs" | wc -l) functions)"
exit "$fail"
