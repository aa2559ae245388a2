# ctest simdvol_bench_swap_report: what simdvol-bench-swap (-DSWAP=...)
# prints for the 16^3 phantom on 64 PEs, run in ${WORK} with
# $SIMDVOL_DATA_DIR an empty directory.
# - The swap's times of a frame are per launch, and say so with the number
#   of stages ("swap launches (ms; N launches for 6 stages)"; they were
#   "swap stages (ms)").
# - With --no-reference the serial figures not measured (ref_ms, ratio,
#   PSNR) are "-", not 0.
# - A brainsmall.den not found is said (naming the file looked for in
#   $SIMDVOL_DATA_DIR), not skipped silently.
set(empty ${WORK}/no-data)
file(REMOVE_RECURSE ${empty})
file(MAKE_DIRECTORY ${empty})
include(${CMAKE_CURRENT_LIST_DIR}/run_tool.cmake)
run_tool(o simdvol-bench-swap ${SWAP} 250 SIMDVOL_DATA_DIR=${empty} --size 16 --runs 1 --pes 64
         --no-reference)
string(FIND "${o}" "(${empty}/brainsmall.den not found: brainsmall skipped" at)
if(at LESS 0)
  message(FATAL_ERROR "no skip naming ${empty}/brainsmall.den:\n${o}")
endif()
# Four frames of the phantom: each a row and its launches (the ';' of
# "(ms; " as ',', not a list separator).
string(REPLACE ";" "," o "${o}")
string(REGEX MATCHALL "\nct-phantom-16 [^\n]*" rows "${o}")
string(REGEX MATCHALL "\n    swap launches \\(ms, [1-6] launch(es)? for 6 stages\\):( [0-9.]+)+"
                      launches "${o}")
list(LENGTH rows nrows)
list(LENGTH launches nlaunches)
if(NOT nrows EQUAL 4 OR NOT nlaunches EQUAL 4)
  message(FATAL_ERROR "not 4 frames, each with 'swap launches (ms; N launches for 6 stages)':\n"
                      "${o}")
endif()
foreach(row IN LISTS rows)
  if(NOT row MATCHES "\\| +- +- +-$")
    message(FATAL_ERROR "--no-reference: ref_ms, ratio and PSNR are not '-':\n${row}")
  endif()
endforeach()
