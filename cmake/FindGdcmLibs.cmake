# Finds GDCM, the Grassroots DICOM library (Debian: libgdcm-dev), for the
# DICOM loader. Debian's own GDCMConfig.cmake works but warns at every
# configure about command-line tools that libgdcm-dev does not install, so
# this module finds the headers and libraries itself and defines
# GdcmLibs::gdcm (gdcmMSFF and the libraries whose symbols simdvol uses
# directly; the shared libraries bring the rest).
find_path(GDCMLIBS_INCLUDE_DIR gdcmImageReader.h PATH_SUFFIXES gdcm-3.0 gdcm)
find_library(GDCMLIBS_MSFF_LIBRARY gdcmMSFF)
find_library(GDCMLIBS_DSED_LIBRARY gdcmDSED)
find_library(GDCMLIBS_COMMON_LIBRARY gdcmCommon)
include(FindPackageHandleStandardArgs)
find_package_handle_standard_args(GdcmLibs
  REQUIRED_VARS GDCMLIBS_MSFF_LIBRARY GDCMLIBS_DSED_LIBRARY GDCMLIBS_COMMON_LIBRARY
                GDCMLIBS_INCLUDE_DIR)
if(GdcmLibs_FOUND AND NOT TARGET GdcmLibs::gdcm)
  add_library(GdcmLibs::gdcm INTERFACE IMPORTED)
  set_target_properties(GdcmLibs::gdcm PROPERTIES
    INTERFACE_INCLUDE_DIRECTORIES "${GDCMLIBS_INCLUDE_DIR}"
    INTERFACE_LINK_LIBRARIES
      "${GDCMLIBS_MSFF_LIBRARY};${GDCMLIBS_DSED_LIBRARY};${GDCMLIBS_COMMON_LIBRARY}")
endif()
