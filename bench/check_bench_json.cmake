# ctest simdvol_bench_harness: runs simdvol-bench (${BENCH}) on a tiny case
# and checks its JSON (${OUT}): the device's details, one case per
# compositing mode, balance sweep count (8 and 0) and --skip-pes (on, off)
# with its stage times, the frame's samples, utilisation and X-Net bytes,
# and direct compositing equal to the reference (PSNR >= 80 dB, or
# identical) either way, the reference timed warm (a warm-up and
# --reference-runs timed renders), no balance time without sweeps, the same samples
# (fewer with skip-pes, which leaves out the PEs with nothing in reach);
# the layout once (the default): the warm-up frame's layout timed, none in
# the timed frames; the kernels' sum within their span within the wall;
# then that a bad option value exits 2 naming the option
# and leaves no JSON behind; then a volume file of the user's (below).
file(REMOVE ${OUT})
execute_process(
  COMMAND ${BENCH} --volumes phantom32 --sizes 64 --orders 1 --pes 64
          --compositing direct,adaptive,mc4s --balance-sweeps 8,0 --skip-pes on,off --repeat 2
          --turntable 4 --reference-runs 3
          --json ${OUT}
  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 0)
  message(FATAL_ERROR "simdvol-bench failed (${rc}):\n${out}\n${err}")
endif()
file(READ ${OUT} text)

macro(get var)
  string(JSON ${var} ERROR_VARIABLE jerr GET "${text}" ${ARGN})
  if(jerr)
    message(FATAL_ERROR "JSON: ${ARGN}: ${jerr}")
  endif()
endmacro()

get(units device compute_units)
if(units LESS 1)
  message(FATAL_ERROR "device.compute_units = ${units}")
endif()
foreach(key name platform_version cpu_model triad_gbs)
  get(v device ${key})
endforeach()
string(JSON ncases LENGTH "${text}" cases)
if(NOT ncases EQUAL 12)
  message(FATAL_ERROR "expected 12 cases, got ${ncases}")
endif()
math(EXPR last "${ncases} - 1")
foreach(i RANGE ${last})
  get(id cases ${i} id)
  get(comp cases ${i} compositing)
  get(pes cases ${i} pes)
  if(NOT pes EQUAL 64)
    message(FATAL_ERROR "${id}: pes = ${pes}")
  endif()
  get(fps cases ${i} fps)
  get(wall cases ${i} wall_ms median)
  get(first cases ${i} first_frame_ms)
  get(match cases ${i} stages_ms match median)
  get(rs cases ${i} stages_ms resample_local median)
  get(samples cases ${i} samples)
  get(util cases ${i} utilisation)
  get(swapped cases ${i} xnet swapped)
  get(bytes cases ${i} xnet swap_bytes)
  get(halo cases ${i} xnet halo_bytes)
  get(sweeps cases ${i} balance_sweeps)
  get(layout cases ${i} layout)
  get(layout_once cases ${i} layout_once_ms)
  get(layout_med cases ${i} stages_ms layout median)
  if(NOT layout STREQUAL "once" OR NOT layout_once GREATER 0 OR NOT layout_med EQUAL 0)
    message(FATAL_ERROR
            "${id}: layout ${layout}, once ${layout_once} ms, timed frames' median ${layout_med} ms")
  endif()
  get(skip_pes cases ${i} skip_pes)
  get(bal cases ${i} stages_ms balance median)
  if(skip_pes STREQUAL "OFF" OR skip_pes STREQUAL "false")
    set(skip_pes OFF)
    if(NOT id MATCHES "/allpe$")
      message(FATAL_ERROR "${id}: skip_pes off but the id does not say so")
    endif()
  elseif(id MATCHES "/allpe")
    message(FATAL_ERROR "${id}: skip_pes ${skip_pes}")
  endif()
  if(sweeps EQUAL 0)
    if(NOT id MATCHES "/b0(/allpe)?$" OR NOT bal EQUAL 0)
      message(FATAL_ERROR "${id}: 0 balance sweeps but balance ${bal} ms")
    endif()
  elseif(NOT sweeps EQUAL 8 OR NOT bal GREATER 0 OR id MATCHES "/b")
    message(FATAL_ERROR "${id}: ${sweeps} balance sweeps, balance ${bal} ms")
  endif()
  # Balancing moves samples between PEs: the total is the matching's, of
  # every PE or (skip-pes: direct, adaptive and mc4s (stratified, exact opacity) all leave them out) of
  # the PEs with something in reach.
  if(skip_pes)
    set(kind skip)
  else()
    set(kind all)
  endif()
  if(NOT DEFINED samples_${kind})
    set(samples_${kind} ${samples})
  elseif(NOT samples EQUAL samples_${kind})
    message(FATAL_ERROR "${id}: ${samples} samples, an earlier case had ${samples_${kind}}")
  endif()
  get(psnr cases ${i} reference psnr_db)
  get(identical cases ${i} reference identical)
  get(ref_ms cases ${i} reference ms)
  get(ref_first cases ${i} reference first_ms)
  get(ref_runs cases ${i} reference runs)
  if(NOT ref_ms GREATER 0 OR NOT ref_first GREATER 0 OR NOT ref_runs EQUAL 3)
    message(FATAL_ERROR "${id}: reference ${ref_ms} ms (warm-up ${ref_first} ms, "
                        "${ref_runs} runs; 3 asked for)")
  endif()
  if(NOT halo GREATER 0)
    message(FATAL_ERROR "${id}: halo bytes ${halo} (64 PEs have neighbours)")
  endif()
  if(samples LESS 1000)
    message(FATAL_ERROR "${id}: samples = ${samples}")
  endif()
  if(util GREATER 1.0 OR util LESS 0.5)
    message(FATAL_ERROR "${id}: utilisation = ${util}")
  endif()
  if(NOT wall GREATER 0 OR NOT match GREATER 0 OR NOT rs GREATER 0)
    message(FATAL_ERROR "${id}: wall ${wall}, match ${match}, resample_local ${rs} ms")
  endif()
  # The frame's kernels summed, within their span, within the frame's wall
  # time: each holds frame by frame, so also for the medians (x <= y in
  # every frame keeps the order of the sorted values).
  get(kern cases ${i} kernels_ms median)
  get(span cases ${i} kernel_span_ms median)
  get(wait cases ${i} longest_wait_ms median)
  if(NOT kern GREATER 0 OR kern GREATER span OR span GREATER wall OR wait LESS 0
     OR wait GREATER span)
    message(FATAL_ERROR "${id}: kernels ${kern} ms, span ${span} ms, wall ${wall} ms, "
                        "longest wait ${wait} ms")
  endif()
  if(comp STREQUAL "direct")
    if(NOT swapped OR bytes LESS 16)
      message(FATAL_ERROR "${id}: direct compositing without swap bytes (${swapped}, ${bytes})")
    endif()
    # Thesis ch. 6.2's bound is per PE, in pixels: 32^3 on 64 PEs has cells
    # of 8 x 8 x 8 voxels, S = (8^2 + 8^2 + 8^2) / 2 = 96 px at voxel
    # sampling, and 3 + 3 swaps: (M + N) S = 576 px. One PE's sends (16 B a
    # pixel) stay within it; all PEs' (swap_bytes) need not.
    get(bound cases ${i} xnet bound_sum_px)
    get(pe_sent cases ${i} xnet max_pe_sent_bytes)
    math(EXPR pe_sent_px "${pe_sent} / 16")
    if(NOT bound EQUAL 576 OR NOT pe_sent_px GREATER 0 OR pe_sent_px GREATER bound
       OR NOT bytes GREATER pe_sent)
      message(FATAL_ERROR "${id}: ch. 6.2 bound ${bound} px (576 expected), one PE sent "
                          "${pe_sent} B = ${pe_sent_px} px, all PEs ${bytes} B")
    endif()
    if(NOT identical AND (psnr STREQUAL "null" OR psnr LESS 80))
      message(FATAL_ERROR "${id}: PSNR against the reference ${psnr} dB < 80")
    endif()
  elseif(comp STREQUAL "adaptive")
    if(swapped OR NOT bytes EQUAL 0)
      message(FATAL_ERROR "${id}: adaptive (whole rays) should not swap (${swapped}, ${bytes})")
    endif()
  endif()
endforeach()
if(NOT samples_skip LESS samples_all)
  message(FATAL_ERROR "skip-pes: ${samples_skip} samples, not fewer than ${samples_all}")
endif()
get(tframes turntables 0 frames)
if(NOT tframes EQUAL 4)
  message(FATAL_ERROR "turntable frames = ${tframes}")
endif()

file(REMOVE ${OUT})
execute_process(COMMAND ${BENCH} --sizes 64,abc --json ${OUT}
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 2 OR NOT err MATCHES "--sizes: 'abc' is not an integer" OR EXISTS ${OUT})
  message(FATAL_ERROR "bad --sizes: exit ${rc}, stderr ${err}")
endif()
execute_process(COMMAND ${BENCH} --compositing direct,mcx
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 2 OR NOT err MATCHES "--compositing")
  message(FATAL_ERROR "bad --compositing: exit ${rc}, stderr ${err}")
endif()
execute_process(COMMAND ${BENCH} --balance-sweeps 8,65
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 2 OR NOT err MATCHES "--balance-sweeps")
  message(FATAL_ERROR "bad --balance-sweeps: exit ${rc}, stderr ${err}")
endif()
execute_process(COMMAND ${BENCH} --skip-pes on,maybe
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 2 OR NOT err MATCHES "--skip-pes")
  message(FATAL_ERROR "bad --skip-pes: exit ${rc}, stderr ${err}")
endif()
execute_process(COMMAND ${BENCH} --layout sometimes
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 2 OR NOT err MATCHES "--layout: 'sometimes' is neither once nor every")
  message(FATAL_ERROR "bad --layout: exit ${rc}, stderr ${err}")
endif()
execute_process(COMMAND ${BENCH} --volumes brainsmall --data ${OUT}.nodata
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 1 OR NOT err MATCHES "brainsmall.den: missing")
  message(FATAL_ERROR "missing requested data: exit ${rc}, stderr ${err}")
endif()
execute_process(COMMAND ${BENCH} --quick --json ${OUT}.nodir/x.json
                RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
if(NOT rc EQUAL 2 OR NOT err MATCHES "--json: directory")
  message(FATAL_ERROR "--json into a missing directory: exit ${rc}, stderr ${err}")
endif()
# A volume file of the user's (${SIMDVOL} writes a 24^3 phantom in
# Hounsfield units): its cases named by its file name, classified ct as
# `simdvol render --classify auto` would, direct compositing equal to the
# reference; a missing one exits 1 naming it.
if(DEFINED SIMDVOL)
  set(vol ${OUT}.user.nrrd)
  execute_process(COMMAND ${SIMDVOL} phantom shepp-logan --size 24 -o ${vol}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "simdvol phantom: exit ${rc}: ${err}")
  endif()
  file(REMOVE ${OUT})
  execute_process(COMMAND ${BENCH} --volumes ${vol} --sizes 32 --pes 64 --compositing direct
                          --repeat 1 --turntable 2 --no-volpack --json ${OUT}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "simdvol-bench --volumes ${vol}: exit ${rc}:\n${out}\n${err}")
  endif()
  file(READ ${OUT} text)
  get_filename_component(vname ${vol} NAME)
  get(cls volumes 0 classifier)
  get(id cases 0 id)
  get(psnr cases 0 reference psnr_db)
  get(identical cases 0 reference identical)
  if(NOT cls STREQUAL "ct" OR NOT id STREQUAL "${vname}/32/o1/direct/P64"
     OR (NOT identical AND (psnr STREQUAL "null" OR psnr LESS 80)))
    message(FATAL_ERROR "volume file: classifier ${cls}, case ${id}, PSNR ${psnr} dB")
  endif()
  # --volume-index: the volume of a 4-D file (index 0 of this 3-D one; 1
  # is past its one volume: exit 1 naming the file).
  file(REMOVE ${OUT})
  execute_process(COMMAND ${BENCH} --volumes ${vol} --volume-index 0 --sizes 32 --pes 64
                          --compositing direct --repeat 1 --turntable 0 --no-volpack
                          --no-reference --json ${OUT}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "simdvol-bench --volume-index 0: exit ${rc}:\n${out}\n${err}")
  endif()
  file(READ ${OUT} text)
  get(id cases 0 id)
  if(NOT id STREQUAL "${vname}@0/32/o1/direct/P64")
    message(FATAL_ERROR "--volume-index 0: case ${id}")
  endif()
  execute_process(COMMAND ${BENCH} --volumes ${vol} --volume-index 1 --sizes 32 --pes 64
                          --no-volpack --no-reference
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 1 OR NOT err MATCHES "user.nrrd: volume index 1 is outside 0..0")
    message(FATAL_ERROR "--volume-index past the volumes: exit ${rc}, stderr ${err}")
  endif()
  execute_process(COMMAND ${BENCH} --volumes ${OUT}.no-such.nii.gz --sizes 32
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 1 OR NOT err MATCHES "no-such.nii.gz: file not found")
    message(FATAL_ERROR "a missing volume file: exit ${rc}, stderr ${err}")
  endif()
  # Two files of one name in two directories: each named by its directory,
  # each compared with its own reference image (the second was compared
  # with the first's, 18.3 dB, under the first's id).
  file(MAKE_DIRECTORY ${OUT}.s1 ${OUT}.s2)
  execute_process(COMMAND ${SIMDVOL} phantom shepp-logan --size 20 -o ${OUT}.s1/v.nrrd
                  RESULT_VARIABLE rc1)
  execute_process(COMMAND ${SIMDVOL} phantom shepp-logan --size 28 -o ${OUT}.s2/v.nrrd
                  RESULT_VARIABLE rc2)
  if(NOT rc1 EQUAL 0 OR NOT rc2 EQUAL 0)
    message(FATAL_ERROR "simdvol phantom: exit ${rc1}, ${rc2}")
  endif()
  file(REMOVE ${OUT})
  execute_process(COMMAND ${BENCH} --volumes ${OUT}.s1/v.nrrd,${OUT}.s2/v.nrrd --sizes 32
                          --pes 64 --compositing direct --repeat 1 --turntable 0 --no-volpack
                          --json ${OUT}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "two volumes of one name: exit ${rc}:\n${out}\n${err}")
  endif()
  file(READ ${OUT} text)
  get_filename_component(d1 ${OUT}.s1 NAME)
  get_filename_component(d2 ${OUT}.s2 NAME)
  foreach(k 0 1)
    math(EXPR n "${k} + 1")
    get(id cases ${k} id)
    get(psnr cases ${k} reference psnr_db)
    get(identical cases ${k} reference identical)
    if(NOT id STREQUAL "${d${n}}/v.nrrd/32/o1/direct/P64"
       OR (NOT identical AND (psnr STREQUAL "null" OR psnr LESS 80)))
      message(FATAL_ERROR "two volumes of one name: case ${k} ${id}, PSNR ${psnr} dB")
    endif()
  endforeach()
  # One volume by two paths: refused as a case given twice.
  execute_process(COMMAND ${BENCH} --volumes ${OUT}.s1/v.nrrd,${OUT}.s1/../${d1}/v.nrrd
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 2 OR NOT err MATCHES "--volumes: .* again: give each volume once")
    message(FATAL_ERROR "one volume by two paths: exit ${rc}, stderr ${err}")
  endif()
  # --json naming the voxels of a detached header (known only once the
  # header is read): refused before any frame, the voxels kept (the JSON
  # replaced them).
  string(REPEAT "A" 4096 voxels)
  file(WRITE ${OUT}.x.raw "${voxels}")
  get_filename_component(raw ${OUT}.x.raw NAME)
  file(WRITE ${OUT}.x.nhdr "NRRD0004\ntype: uchar\ndimension: 3\nsizes: 16 16 16\n"
                            "encoding: raw\ndata file: ${raw}\n\n")
  execute_process(COMMAND ${BENCH} --volumes ${OUT}.x.nhdr --sizes 32 --no-volpack
                          --json ${OUT}.x.raw
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  file(READ ${OUT}.x.raw kept)
  if(NOT rc EQUAL 2 OR NOT err MATCHES "--json: writing .* would replace"
     OR NOT kept STREQUAL voxels OR NOT out STREQUAL "")
    message(FATAL_ERROR "--json over a detached header's voxels: exit ${rc}, stderr ${err}")
  endif()
  # --scaling beside --reference-runs and --volpack-runs (its children were
  # given those with --no-reference and --no-volpack, and refused them
  # after every case had run).
  file(REMOVE ${OUT})
  file(GLOB scratch_before LIST_DIRECTORIES true /tmp/simdvol-bench-*)
  execute_process(COMMAND ${BENCH} --volumes ${vol} --sizes 32 --pes 64 --compositing direct
                          --repeat 1 --turntable 0 --reference-runs 1 --volpack-runs 1
                          --scaling 1,2 --json ${OUT}
                  RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 0)
    message(FATAL_ERROR "--scaling with --reference-runs: exit ${rc}:\n${out}\n${err}")
  endif()
  # The children's directory removed (it was left where a child failed).
  file(GLOB scratch_after LIST_DIRECTORIES true /tmp/simdvol-bench-*)
  list(REMOVE_ITEM scratch_after ${scratch_before} "")
  if(scratch_after)
    message(FATAL_ERROR "--scaling left its children's directory: ${scratch_after}")
  endif()
  file(READ ${OUT} text)
  get(t2 scaling 0 stages wall t2)
  file(REMOVE_RECURSE ${vol} ${OUT} ${OUT}.s1 ${OUT}.s2 ${OUT}.x.raw ${OUT}.x.nhdr)
endif()
# simdvol-bench-volpack's JSON: a volume's name with a tab and a byte that
# is not UTF-8 (written as they were, the file was not JSON); --quick before
# --sizes or after it, the sizes given kept (--sizes 16 --quick rendered
# 256 x 256).
if(DEFINED VOLPACK AND EXISTS "${BRAINSMALL}")
  string(ASCII 9 tab)
  string(ASCII 255 notutf8)
  set(link "${OUT}.brain${tab}small${notutf8}.den")
  file(CREATE_LINK "${BRAINSMALL}" "${link}" SYMBOLIC)
  foreach(order "--sizes;16;--quick" "--quick;--sizes;16")
    file(REMOVE ${OUT})
    execute_process(COMMAND ${VOLPACK} --data ${link} ${order} --runs 0 --ref-runs 0 --bf-runs 0
                            --no-opencl --no-matched --no-brute-force --json ${OUT}
                    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
    if(NOT rc EQUAL 0)
      message(FATAL_ERROR "simdvol-bench-volpack ${order}: exit ${rc}:\n${out}\n${err}")
    endif()
    file(READ ${OUT} text)
    get(volume volume)
    get(size cases 0 size)
    if(NOT volume MATCHES "^.*brain\tsmall.*\\.den$" OR NOT size EQUAL 16)
      message(FATAL_ERROR "simdvol-bench-volpack ${order}: volume '${volume}', size ${size}")
    endif()
  endforeach()
  file(REMOVE ${link} ${OUT})
endif()
# A case that fails (an allocation failure injected into the first case's
# cell buffer) is skipped, saying why, and the run, its JSON written, exits
# 1 naming it (it exited 0, the run's figures looking whole); with
# --scaling its child, whose first case fails too, exits 0 and its JSON
# says so (its exit 1 lost the whole run: no JSON, no summary).
function(run_failing_case)
  file(REMOVE ${OUT})
  execute_process(
    COMMAND ${CMAKE_COMMAND} -E env "SIMDVOL_FAIL_ALLOCATION=cell buffer"
            ${BENCH} --volumes phantom16 --sizes 32 --compositing direct --pes 64,8
            --turntable 0 --no-volpack ${ARGN} --json ${OUT}
    RESULT_VARIABLE rc OUTPUT_VARIABLE out ERROR_VARIABLE err)
  if(NOT rc EQUAL 1 OR NOT err MATCHES "1 case failed .*: phantom16/32/o1/direct/P64\n$"
     OR NOT EXISTS ${OUT})
    message(FATAL_ERROR "a failed case (${ARGN}): exit ${rc}, JSON written: ${OUT}\n${out}\n${err}")
  endif()
endfunction()
run_failing_case(--reference-runs 1)
file(READ ${OUT} text)
get(skip0 cases 0 skipped)
string(JSON skip1 ERROR_VARIABLE jerr GET "${text}" cases 1 skipped)
if(NOT skip0 MATCHES "injected by SIMDVOL_FAIL_ALLOCATION" OR NOT jerr)
  message(FATAL_ERROR "a failed case: case 0 skipped '${skip0}', case 1 '${skip1}'")
endif()
run_failing_case(--no-reference --scaling 1)
file(READ ${OUT} text)
get(t1 scaling 0 stages wall t1)
file(REMOVE ${OUT})
message(STATUS "simdvol-bench harness: ${ncases} cases checked")
