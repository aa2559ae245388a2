# Finds MetaIO, Kitware's reader of MetaImage files (.mha, .mhd), as ITK
# ships it (Debian: libinsighttoolkit5-dev; the library libITKMetaIO and
# its headers under include/ITK-5.x). Only this library of ITK is linked,
# not ITK's pipeline, so ITK's own (large) CMake package is not loaded.
# Defines MetaIO::metaio (include as <metaImage.h>).
find_path(METAIO_INCLUDE_DIR metaImage.h PATH_SUFFIXES ITK-5.4 ITK-5.3 ITK-5.2 ITK-5.1 ITK-5.0)
find_library(METAIO_LIBRARY NAMES ITKMetaIO-5.4 ITKMetaIO-5.3 ITKMetaIO-5.2 ITKMetaIO-5.1
                                  ITKMetaIO-5.0 ITKMetaIO)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(MetaIO REQUIRED_VARS METAIO_LIBRARY METAIO_INCLUDE_DIR)
if(MetaIO_FOUND AND NOT TARGET MetaIO::metaio)
  add_library(MetaIO::metaio UNKNOWN IMPORTED)
  set_target_properties(MetaIO::metaio PROPERTIES
    IMPORTED_LOCATION "${METAIO_LIBRARY}"
    INTERFACE_INCLUDE_DIRECTORIES "${METAIO_INCLUDE_DIR}")
endif()
