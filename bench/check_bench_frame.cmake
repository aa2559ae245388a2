# ctest simdvol_bench_frame_report: what simdvol-bench-frame (-DFRAME=...)
# prints.
# - With --no-reference the serial figures not measured (ref r+l, ref/dev)
#   are "-", not 0.0; with the reference they are numbers.
# - --whole finds brainsmall.den where the other tools do, from any working
#   directory (-DWORK=..., not the source tree): in $SIMDVOL_DATA_DIR where
#   set (an empty directory here: the message names the file looked for),
#   else in the source tree's data/ (-DDATA=...; the case is rendered where
#   scripts/fetch-data has fetched it, else the message names that file).
#   It looked for data/brainsmall.den under the working directory.
# - The swap's times are per launch: "N launch(es), 6 stages" for 64 PEs
#   (it said "N stages" of the launches).

# run_frame(OUT ENV-ARG ARG...): runs the tool under `cmake -E env ENV-ARG`
# in ${WORK}, fails on a non-zero exit, stdout in OUT.
include(${CMAKE_CURRENT_LIST_DIR}/run_tool.cmake)
function(run_frame out env)
  run_tool(o simdvol-bench-frame ${FRAME} 250 ${env} ${ARGN})
  set(${out} "${o}" PARENT_SCOPE)
endfunction()

file(MAKE_DIRECTORY ${WORK})

# The table's row for view 0: "... | ref m+b ref r+l ref/dev Gld/s | ...".
set(args --size 32 --runs 1 --views 0 --pes 64)
run_frame(o --unset=SIMDVOL_DATA_DIR ${args} --no-reference)
string(REGEX MATCH "\n +0 [^\n]*" row "${o}")
if(NOT row MATCHES "\\| +[0-9.]+ +- +- +[0-9.]+ \\|")
  message(FATAL_ERROR "--no-reference: ref r+l and ref/dev are not '-':\n${row}")
endif()
run_frame(o --unset=SIMDVOL_DATA_DIR ${args})
string(REGEX MATCH "\n +0 [^\n]*" row "${o}")
if(NOT row MATCHES "\\| +[0-9.]+ +[0-9]+\\.[0-9] +[0-9]+\\.[0-9] +[0-9.]+ \\|")
  message(FATAL_ERROR "with the reference: ref r+l and ref/dev are not numbers:\n${row}")
endif()

# --whole with $SIMDVOL_DATA_DIR an empty directory.
set(empty ${WORK}/no-data)
file(REMOVE_RECURSE ${empty})
file(MAKE_DIRECTORY ${empty})
run_frame(o SIMDVOL_DATA_DIR=${empty} --whole --runs 1 --pes 64)
string(FIND "${o}" "(${empty}/brainsmall.den not found: brainsmall skipped" at)
if(at LESS 0)
  message(FATAL_ERROR "--whole, SIMDVOL_DATA_DIR=${empty}: no skip naming its file:\n${o}")
endif()
string(REGEX MATCHALL "swap [0-9.]+ \\([0-9]+ launch(es)?, 6 stages\\)" swaps "${o}")
list(LENGTH swaps n)
if(NOT n EQUAL 2)
  message(FATAL_ERROR "--whole --pes 64: not two 'swap T (N launches, 6 stages)':\n${o}")
endif()

# --whole without it, from ${WORK}: the source tree's data/.
run_frame(o --unset=SIMDVOL_DATA_DIR --whole --runs 1 --pes 64)
if(EXISTS ${DATA}/brainsmall.den)
  if(NOT o MATCHES "\nbrainsmall -> 256\\^2: reference [0-9.]+ ms")
    message(FATAL_ERROR "--whole from ${WORK}: ${DATA}/brainsmall.den not rendered:\n${o}")
  endif()
else()
  string(FIND "${o}" "(${DATA}/brainsmall.den not found: brainsmall skipped" at)
  if(at LESS 0)
    message(FATAL_ERROR "--whole from ${WORK}: no skip naming ${DATA}/brainsmall.den:\n${o}")
  endif()
endif()
