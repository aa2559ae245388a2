# Finds niftilib's NIfTI-1 I/O library (Debian: libnifti2-dev).
# Debian's own NIFTIConfig.cmake points at /usr/lib instead of the multiarch
# directory, so it cannot be used; this module defines NiftiIO::niftiio.
find_path(NIFTIIO_INCLUDE_DIR nifti1_io.h PATH_SUFFIXES nifti)
find_library(NIFTIIO_LIBRARY niftiio)
find_library(NIFTIIO_ZNZ_LIBRARY znz)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(NiftiIO
  REQUIRED_VARS NIFTIIO_LIBRARY NIFTIIO_ZNZ_LIBRARY NIFTIIO_INCLUDE_DIR)
if(NiftiIO_FOUND AND NOT TARGET NiftiIO::niftiio)
  find_package(ZLIB REQUIRED)
  add_library(NiftiIO::znz UNKNOWN IMPORTED)
  set_target_properties(NiftiIO::znz PROPERTIES
    IMPORTED_LOCATION "${NIFTIIO_ZNZ_LIBRARY}"
    INTERFACE_LINK_LIBRARIES ZLIB::ZLIB)
  add_library(NiftiIO::niftiio UNKNOWN IMPORTED)
  set_target_properties(NiftiIO::niftiio PROPERTIES
    IMPORTED_LOCATION "${NIFTIIO_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${NIFTIIO_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "NiftiIO::znz;m")
endif()
