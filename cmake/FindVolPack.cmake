# Finds VolPack 1.0b3 (Debian: libvolpack1-dev: volpack.h, libvolpack.so),
# Lacroute's shear-warp volume renderer, used as an optional peer renderer by
# the benchmarks (bench/volpack_peer.*) and tests/volpack. Defines
# VolPack::volpack and VolPack_FOUND; nothing else needs it.
find_path(VOLPACK_INCLUDE_DIR volpack.h)
find_library(VOLPACK_LIBRARY volpack)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(VolPack REQUIRED_VARS VOLPACK_LIBRARY VOLPACK_INCLUDE_DIR)
mark_as_advanced(VOLPACK_INCLUDE_DIR VOLPACK_LIBRARY)
if(VolPack_FOUND AND NOT TARGET VolPack::volpack)
  add_library(VolPack::volpack UNKNOWN IMPORTED)
  set_target_properties(VolPack::volpack PROPERTIES
    IMPORTED_LOCATION "${VOLPACK_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${VOLPACK_INCLUDE_DIR}")
  # volpack.h uses the math library (libvolpack links it itself).
  find_library(VOLPACK_M_LIBRARY m)
  if(VOLPACK_M_LIBRARY)
    set_property(TARGET VolPack::volpack APPEND PROPERTY INTERFACE_LINK_LIBRARIES "${VOLPACK_M_LIBRARY}")
  endif()
endif()
