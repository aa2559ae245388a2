# ctest simdvol_bench_args: every bench tool refuses a bad command line
# before any device work. Each tool (its path in -D<TOOL>=..., a tool not
# passed is skipped, as simdvol-bench-volpack is without VolPack and
# simdvol-bench without nlohmann-json) runs with
# bad arguments: a value out of range, not a number, a trailing garbage
# integer, a bad list item, a missing value, an unknown option. Each must
# exit 2 with "<tool>: <option>: <problem>" and the usage line on stderr and
# nothing on stdout (no device was opened, nothing was measured).
set(checked 0)

# expect_bad(TOOL OPTION ARG...): runs ${TOOL} ARG... and checks the refusal
# names OPTION.
function(expect_bad tool option)
  if(NOT DEFINED ${tool})
    return()
  endif()
  set(exe ${${tool}})
  get_filename_component(name ${exe} NAME)
  execute_process(COMMAND ${exe} ${ARGN} RESULT_VARIABLE rc OUTPUT_VARIABLE out
                  ERROR_VARIABLE err TIMEOUT 30)
  string(JOIN " " call ${name} ${ARGN})
  if(NOT rc STREQUAL "2")
    message(FATAL_ERROR "${call}: exit ${rc}, expected 2\nstdout: ${out}\nstderr: ${err}")
  endif()
  string(FIND "${err}" "${name}: ${option}: " at)
  if(NOT at EQUAL 0)
    message(FATAL_ERROR "${call}: stderr does not begin with '${name}: ${option}: ':\n${err}")
  endif()
  string(FIND "${err}" "usage: ${name}" at)
  if(at LESS 0)
    message(FATAL_ERROR "${call}: no usage line on stderr:\n${err}")
  endif()
  if(NOT out STREQUAL "")
    message(FATAL_ERROR "${call}: printed on stdout (work started?):\n${out}")
  endif()
  math(EXPR n "${checked} + 1")
  set(checked ${n} PARENT_SCOPE)
endfunction()

expect_bad(FRAME --runs --runs 0)
expect_bad(FRAME --size --size 12abc)
expect_bad(FRAME --views --views 0,,30)
expect_bad(FRAME --pes --whole --pes 1000)
expect_bad(FRAME --kernels --whole --kernels)
expect_bad(FRAME --frob --frob)

expect_bad(MATCH --repeat --repeat -1)
expect_bad(MATCH --sweeps --sweeps 65)
expect_bad(MATCH --pes --pes)
expect_bad(MATCH --random --random -1)

expect_bad(SHADE --runs --runs abc)
expect_bad(SHADE --size --size 4)
expect_bad(SHADE --classifier --classifier no-such-classifier)
expect_bad(SHADE --volume --volume /no/such/volume.den)
expect_bad(SHADE --volume --size 64 --volume /no/such/volume.den)
expect_bad(SHADE --volume --volume)

expect_bad(SWAP --size --size garbage)
expect_bad(SWAP --order --order 4)
expect_bad(SWAP --layout --layout diagonal)

expect_bad(VOLPACK --sizes --sizes 256,x)
expect_bad(VOLPACK --pixel-centre --pixel-centre 1e999)
expect_bad(VOLPACK --turntable --turntable 0)

expect_bad(FIG7 --seed --out . --seed -3)
expect_bad(FIG7 --view --out . --view 1,2)
expect_bad(FIG7 --out --size 64)

expect_bad(TABLES --order --order 2)
expect_bad(TABLES --sweeps --sweeps 65)
expect_bad(TABLES --views --views 0,nan)
expect_bad(TABLES --markdown --markdown ${CMAKE_CURRENT_LIST_DIR}/no-such-dir/t.md)

expect_bad(OPTIONS --variant --frames 3)
expect_bad(OPTIONS --frames --frames 0 --variant -DSV_VOX_PF=0)
expect_bad(OPTIONS --view --view 1,2 --variant -DSV_VOX_PF=0)
expect_bad(OPTIONS --volume --volume /no/such/volume.den --variant -DSV_VOX_PF=0)
expect_bad(OPTIONS --classifier --classifier no-such-classifier --variant -DSV_VOX_PF=0)
expect_bad(OPTIONS --order --order 4 --variant -DSV_VOX_PF=0)

expect_bad(BENCH --repeat --repeat 3,4)
expect_bad(BENCH --turntable --turntable 721)
expect_bad(BENCH --reference-runs --reference-runs 0)
expect_bad(BENCH --sizes --sizes 256,0)
expect_bad(BENCH --volumes --volumes phantom64,head.txt)
expect_bad(BENCH --volume-index --volume-index -1)
expect_bad(BENCH --volume-index --volumes phantom64,brainsmall --volume-index 1)
# A case twice (two cases of one id in the JSON), a view far outside a
# turn, runs of what is not run.
expect_bad(BENCH --sizes --sizes 256,256)
expect_bad(BENCH --volumes --volumes phantom64,phantom64)
expect_bad(BENCH --skip-pes --skip-pes on,on)
expect_bad(BENCH --view --view 1e300,0,0)
expect_bad(BENCH --reference-runs --no-reference --reference-runs 3)
expect_bad(BENCH --volpack-runs --volpack-runs 2 --no-volpack)
expect_bad(BENCH --volumes --volumes phantom)
expect_bad(BENCH --data --volumes phantom16 --data ${CMAKE_CURRENT_BINARY_DIR})
expect_bad(SWAP --swap-only --comm-only --swap-only)
expect_bad(MATCH --random --random 5 --no-table)

# Names, checked before any work (twenty-third session): an output naming a
# volume the run reads (it was replaced by the JSON), an output that is a
# directory (found after the frames), a --brain that does not exist (it
# was skipped), an --out that is a file or holds a directory where a
# figure goes (fig7.csv
# was written before fig7.png failed). Empty names too (--volume "" rendered
# the phantom; --json "" failed after the frames), each run here apart:
# CMake drops the empty items of expect_bad's ARGN.
set(scratch "${CMAKE_CURRENT_BINARY_DIR}/bench_args_scratch")
file(REMOVE_RECURSE "${scratch}")
file(MAKE_DIRECTORY "${scratch}/adir" "${scratch}/fig/fig7.png")
file(WRITE "${scratch}/v.nrrd" "keep")
file(WRITE "${scratch}/a.hdr" "keep")
file(WRITE "${scratch}/a.img" "keep")
file(WRITE "${scratch}/afile" "keep")
expect_bad(BENCH --json --volumes ${scratch}/v.nrrd --json ${scratch}/v.nrrd)
expect_bad(BENCH --json --json ${scratch}/a.img --volumes ${scratch}/a.hdr)
expect_bad(BENCH --json --json ${scratch}/adir)
expect_bad(VOLPACK --json --json ${scratch}/v.nrrd --data ${scratch}/v.nrrd)
expect_bad(VOLPACK --write-images --write-images ${scratch}/afile)
expect_bad(FRAME --brain --whole --brain ${scratch}/missing.den)
expect_bad(SWAP --brain --brain ${scratch}/missing.den)
expect_bad(FIG7 --brain --out ${scratch}/out --brain ${scratch}/missing.den)
expect_bad(FIG7 --out --out ${scratch}/afile)
expect_bad(FIG7 --out --out ${scratch}/fig)
# A directory that cannot be made (a file in the way of its parent) was a
# bare "filesystem error" after the arguments were taken.
expect_bad(FIG7 --out --out ${scratch}/afile/sub)
expect_bad(VOLPACK --write-images --write-images ${scratch}/afile/sub)
# A directory in which no file can be made (/proc: access(2) says yes to
# root there), found only as the JSON or the CSV was written, after every
# case had run; --turntable 1 (it timed no frame and printed 0 ms); one
# phantom or compositing twice under two names (two cases of one id).
expect_bad(BENCH --json --json /proc/simdvol-bench.json)
expect_bad(VOLPACK --json --json /proc/simdvol-bench.json)
expect_bad(FIG7 --out --out /proc)
expect_bad(TABLES --markdown --markdown /proc/tables.md)
expect_bad(BENCH --turntable --turntable 1)
expect_bad(TABLES --image --image 256)
expect_bad(BENCH --volumes --volumes phantom16,phantom016)
expect_bad(BENCH --compositing --compositing mc16,mc016)
if(DEFINED BENCH)  # naming both as they were given ('mc16' was given twice)
  foreach(pair "mc16,mc016;'mc016' is 'mc16'" "mc016,mc16;'mc16' is 'mc016'"
          "mc016,mc0016;'mc0016' is 'mc016'")
    list(GET pair 0 list)
    list(GET pair 1 want)
    execute_process(COMMAND ${BENCH} --compositing ${list} RESULT_VARIABLE rc
                    ERROR_VARIABLE err OUTPUT_QUIET TIMEOUT 30)
    if(NOT err MATCHES "^simdvol-bench: --compositing: ${want} again: give each")
      message(FATAL_ERROR "--compositing ${list}: ${err}")
    endif()
  endforeach()
endif()
function(expect_empty_refused tool option)
  if(NOT DEFINED ${tool})
    return()
  endif()
  execute_process(COMMAND ${${tool}} ${option} "" ${ARGN} RESULT_VARIABLE rc
                  ERROR_VARIABLE err OUTPUT_VARIABLE out TIMEOUT 30)
  get_filename_component(name ${${tool}} NAME)
  string(FIND "${err}" "${name}: ${option}: needs a name, not an empty one" at)
  if(NOT rc STREQUAL "2" OR NOT at EQUAL 0 OR NOT out STREQUAL "")
    message(FATAL_ERROR "${name} ${option} '': exit ${rc}\nstdout: ${out}\nstderr: ${err}")
  endif()
  math(EXPR n "${checked} + 1")
  set(checked ${n} PARENT_SCOPE)
endfunction()
expect_empty_refused(BENCH --json --volumes phantom16)
expect_empty_refused(OPTIONS --volume --variant -DSV_VOX_PF=0)
expect_empty_refused(SHADE --volume)
expect_empty_refused(TABLES --markdown)
expect_empty_refused(FIG7 --out)
foreach(f v.nrrd a.hdr a.img afile)
  file(READ "${scratch}/${f}" kept)
  if(NOT kept STREQUAL "keep")
    message(FATAL_ERROR "${f} was written: '${kept}'")
  endif()
endforeach()
if(EXISTS "${scratch}/out")
  message(FATAL_ERROR "${scratch}/out was made for a run that was refused")
endif()

if(checked LESS 20)
  message(FATAL_ERROR "only ${checked} refusals checked: a tool path is missing")
endif()
message(STATUS "${checked} bad command lines refused")
