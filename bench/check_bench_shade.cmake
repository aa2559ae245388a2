# ctest simdvol_bench_shade_report: what simdvol-bench-shade (-DSHADE=...)
# prints. The PE-major / flat ratio of the fused kernel is a number only
# where the flat fused kernel ran (a width that is a multiple of 16: the
# 32^3 phantom) and "n/a" with the reason where it did not (24^3): it was
# 0.00, which reads as the goal met. Its --help names every volume format
# that `simdvol render --help` (-DSIMDVOL=...) names, but .raw (its layout
# cannot be given here).

# run_shade(OUT ARG...): runs the tool, fails on a non-zero exit, stdout in OUT.
include(${CMAKE_CURRENT_LIST_DIR}/run_tool.cmake)
function(run_shade out)
  run_tool(o simdvol-bench-shade ${SHADE} 120 "" ${ARGN})
  set(${out} "${o}" PARENT_SCOPE)
endfunction()

run_shade(o24 --size 24 --runs 1 --no-reference)
string(REGEX MATCH "PE-major / flat: [^\n]*" line "${o24}")
string(CONCAT want "fused shade\\+classify n/a \\(the flat fused kernel takes rows of a "
       "multiple of 16 voxels; this volume's rows are 24; --sweep compares the scalar")
if(NOT line MATCHES "${want}")
  message(FATAL_ERROR "24^3: the fused ratio is not n/a with its reason:\n${line}")
endif()
if(line MATCHES "goal")
  message(FATAL_ERROR "24^3: a goal beside a ratio not measured:\n${line}")
endif()

run_shade(o32 --size 32 --runs 1 --no-reference)
string(REGEX MATCH "PE-major / flat: [^\n]*" line "${o32}")
if(NOT line MATCHES "fused shade\\+classify [0-9]+\\.[0-9][0-9] \\(goal <= 1\\.5\\)$")
  message(FATAL_ERROR "32^3: no fused ratio:\n${line}")
endif()

run_shade(help --help)
execute_process(COMMAND ${SIMDVOL} render --help RESULT_VARIABLE rc OUTPUT_VARIABLE render_help
                ERROR_VARIABLE e TIMEOUT 30)
string(REGEX MATCH "volume file \\([^\n]*" formats "${render_help}")
if(NOT rc STREQUAL "0" OR formats STREQUAL "")
  message(FATAL_ERROR "simdvol render --help: exit ${rc}, no 'volume file (...)':\n${render_help}")
endif()
string(REGEX MATCHALL "\\.[a-z][a-z0-9]*(\\.gz)?" endings "${formats}")
list(REMOVE_ITEM endings .raw)
list(APPEND endings DICOM)
string(REPLACE "\n" " " flat_help "${help}")
set(missing "")
foreach(e IN LISTS endings)
  string(FIND "${flat_help}" "${e}" at)
  if(at LESS 0)
    list(APPEND missing ${e})
  endif()
endforeach()
if(missing)
  message(FATAL_ERROR "simdvol-bench-shade --help lacks ${missing}, which the loader reads:\n"
                      "${help}")
endif()
