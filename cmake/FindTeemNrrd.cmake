# Finds teem (Debian: libteem-dev), used for NRRD. Debian's TeemConfig.cmake
# points at the package's build directory, so it cannot be used; this module
# defines Teem::teem.
find_path(TEEM_INCLUDE_DIR teem/nrrd.h)
find_library(TEEM_LIBRARY teem)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(TeemNrrd REQUIRED_VARS TEEM_LIBRARY TEEM_INCLUDE_DIR)
if(TeemNrrd_FOUND AND NOT TARGET Teem::teem)
  add_library(Teem::teem UNKNOWN IMPORTED)
  set_target_properties(Teem::teem PROPERTIES
    IMPORTED_LOCATION "${TEEM_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${TEEM_INCLUDE_DIR}")
endif()
