# run_tool(OUT NAME EXE TIMEOUT ENV ARG...): runs EXE with ARG... under
# `cmake -E env ENV` (a list of NAME=VALUE and --unset=NAME, or "" for
# none), in ${WORK} where the script defines it; fails naming the call
# (NAME ARG...) on a non-zero exit; stdout in OUT. Included by the
# check_bench_*.cmake scripts.
function(run_tool out name exe timeout env)
  set(wd)
  if(DEFINED WORK)
    set(wd WORKING_DIRECTORY ${WORK})
  endif()
  execute_process(COMMAND ${CMAKE_COMMAND} -E env ${env} ${exe} ${ARGN} ${wd}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE o ERROR_VARIABLE e TIMEOUT ${timeout})
  if(NOT rc STREQUAL "0")
    string(JOIN " " call ${name} ${ARGN})
    message(FATAL_ERROR "${call}: exit ${rc}\nstdout: ${o}\nstderr: ${e}")
  endif()
  set(${out} "${o}" PARENT_SCOPE)
endfunction()
