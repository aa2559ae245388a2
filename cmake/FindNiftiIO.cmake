# Finds niftilib's NIfTI I/O library, nifti2_io (Debian: libnifti2-dev),
# which reads NIfTI-1, NIfTI-2 and Analyze 7.5 headers. Its functions share
# their names with the older NIfTI-1-only libniftiio, so only this one is
# linked. Debian's own NIFTIConfig.cmake points at /usr/lib instead of the
# multiarch directory, so it cannot be used; this module defines
# NiftiIO::niftiio (include as <nifti2_io.h>).
find_path(NIFTI2IO_INCLUDE_DIR nifti2_io.h PATH_SUFFIXES nifti)
find_library(NIFTI2IO_LIBRARY nifti2)
find_library(NIFTI2IO_ZNZ_LIBRARY znz)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(NiftiIO
  REQUIRED_VARS NIFTI2IO_LIBRARY NIFTI2IO_ZNZ_LIBRARY NIFTI2IO_INCLUDE_DIR)
if(NiftiIO_FOUND AND NOT TARGET NiftiIO::niftiio)
  find_package(ZLIB REQUIRED)
  add_library(NiftiIO::znz UNKNOWN IMPORTED)
  set_target_properties(NiftiIO::znz PROPERTIES
    IMPORTED_LOCATION "${NIFTI2IO_ZNZ_LIBRARY}"
    INTERFACE_LINK_LIBRARIES ZLIB::ZLIB)
  add_library(NiftiIO::niftiio UNKNOWN IMPORTED)
  set_target_properties(NiftiIO::niftiio PROPERTIES
    IMPORTED_LOCATION "${NIFTI2IO_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${NIFTI2IO_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES "NiftiIO::znz;m")
endif()
