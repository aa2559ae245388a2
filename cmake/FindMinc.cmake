# Finds libminc (Debian: libminc-dev), the MINC reader: its C++ reader
# minc_1_reader (libminc_io) over the MINC1/MINC2 library (libminc2), which
# reads MINC1 (netCDF) and MINC2 (HDF5) files. Debian ships no CMake package
# for it. Defines Minc::minc (include as <minc_1_rw.h>).
find_path(MINC_INCLUDE_DIR minc_1_rw.h)
find_library(MINC_IO_LIBRARY minc_io)
find_library(MINC2_LIBRARY minc2)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(Minc REQUIRED_VARS MINC_IO_LIBRARY MINC2_LIBRARY MINC_INCLUDE_DIR)
if(Minc_FOUND AND NOT TARGET Minc::minc)
  add_library(Minc::minc INTERFACE IMPORTED)
  set_target_properties(Minc::minc PROPERTIES
    INTERFACE_INCLUDE_DIRECTORIES "${MINC_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "${MINC_IO_LIBRARY};${MINC2_LIBRARY}")
endif()
