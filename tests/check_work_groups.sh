#!/usr/bin/env bash
# The CLI's frames on a device that takes fewer work-items in a work-group
# than simdvol's launches ask for (a GPU's CL_DEVICE_MAX_WORK_GROUP_SIZE of
# 256, or a kernel's CL_KERNEL_WORK_GROUP_SIZE of 64), as PoCL's
# POCL_MAX_WORK_GROUP_SIZE makes its CPU device (tests simdvol_work_groups_1,
# _16, _64 set it): every frame equal, every float of its RGBA, to the same
# render without the limit. The kernels read only their global ids, but for
# the fused swap (a work-group of 2^m, fewer stages in one launch) and the
# reqd_work_group_size kernels (WGS, fewer where the device takes fewer), so
# the host's smaller local sizes change no arithmetic. Before, these renders
# failed with CL_INVALID_WORK_GROUP_SIZE (-54) in simdvol_layout (limits
# below 64), simdvol_swap_stages (64) or simdvol_display (128).
#   tests/check_work_groups.sh SIMDVOL_CLI
set -uo pipefail
cli=${1:?usage: check_work_groups.sh SIMDVOL_CLI}
limit=${POCL_MAX_WORK_GROUP_SIZE:?the ctest sets POCL_MAX_WORK_GROUP_SIZE}
dir=$(mktemp -d)
trap 'rm -rf "$dir"' EXIT
fail=0
# The limit reaches the device (else the test would compare a render with itself).
if ! "$cli" devices 2>&1 | grep -q "max work-group size $limit\$"; then
  echo "FAIL: the device does not take POCL_MAX_WORK_GROUP_SIZE=$limit:" >&2
  "$cli" devices >&2
  exit 1
fi
# Small volumes, so that each render takes a fraction of a second: the
# default 8,192 PEs (the fused swap's seven stages, the balance), direct at
# order 1 on an oblique view; per sub-ray Monte Carlo with allocation at
# order 3 and pixel sampling; adaptive at order 0 in the hierarchical layout,
# a turntable of two frames keeping a mixture classification.
cases=(
  "--phantom-size 40 --size 48x40 --view 20,35,10"
  "--phantom-size 32 --size 40x40 --order 3 --sampling pixel --composite mc --mc-scope subray --allocate --samples 4 --pe 512"
  "--phantom-size 32 --size 40x32 --order 0 --composite adaptive --layout hierarchical --pe 64 --classify mri --frames 2 --step 40"
)
for args in "${cases[@]}"; do
  # shellcheck disable=SC2086 # (the options word-split on purpose)
  if ! env -u POCL_MAX_WORK_GROUP_SIZE "$cli" render $args -o "$dir/ref.tif" >/dev/null 2>"$dir/err" ||
    ! "$cli" render $args -o "$dir/lim.tif" >/dev/null 2>>"$dir/err"; then
    echo "FAIL: render $args (limit $limit):" >&2
    cat "$dir/err" >&2
    fail=1
    continue
  fi
  for ref in "$dir"/ref*.tif; do
    lim="$dir/lim${ref#"$dir"/ref}"
    out=$("$cli" compare "$lim" "$ref" 2>&1)
    if [[ "$out" != *$'max_abs_diff 0\n'* && "$out" != *"max_abs_diff 0" ]]; then
      echo "FAIL: render $args, $(basename "$ref"): limit $limit against none: $out" >&2
      fail=1
    fi
  done
  rm -f "$dir"/*.tif
done
exit $fail
