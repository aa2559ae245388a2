# ctest simdvol_repro_tables_image: simdvol-repro-tables (-DTABLES=...)
# takes no image size. The cost model samples on the volume's grid (voxel
# sampling, as the thesis) and does not count the warp to an output image,
# so --image N changed only the "N^2 image" of a paragraph, no figure: it
# is refused (exit 2, naming it, with the usage, which no longer offers
# it), and the paragraph says "voxel sampling" in its place.
execute_process(COMMAND ${TABLES} --image 512 RESULT_VARIABLE rc OUTPUT_VARIABLE out
                ERROR_VARIABLE err TIMEOUT 60)
if(NOT rc STREQUAL "2" OR NOT out STREQUAL "")
  message(FATAL_ERROR "--image 512: exit ${rc} (want 2), stdout:\n${out}\nstderr:\n${err}")
endif()
string(FIND "${err}" "simdvol-repro-tables: --image: does nothing: " at)
if(NOT at EQUAL 0)
  message(FATAL_ERROR "--image 512: the refusal does not say it does nothing:\n${err}")
endif()
if(err MATCHES "usage:[^\n]*--image")
  message(FATAL_ERROR "--image 512: the usage still offers --image:\n${err}")
endif()

execute_process(COMMAND ${TABLES} --views 30 RESULT_VARIABLE rc OUTPUT_VARIABLE out
                ERROR_VARIABLE err TIMEOUT 120)
if(NOT rc STREQUAL "0")
  message(FATAL_ERROR "--views 30: exit ${rc}\n${err}")
endif()
set(want "\\*\\*View \\(0, 30, 0\\)\\*\\*, 256\\^3 volume [^\n]*, voxel sampling, order 1,")
if(out MATCHES "\\^2 image" OR NOT out MATCHES "${want}")
  message(FATAL_ERROR "--views 30: the view's paragraph does not say voxel sampling in place "
                      "of an image size:\n${out}")
endif()
