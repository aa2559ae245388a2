# Installation and the CMake package (included last by the top-level
# CMakeLists.txt). `cmake --install <build> --prefix <p>` puts
#   lib/libsimdvol_core.a, lib/libsimdvol_cl.a   (static, PIC; or .so with
#                                                 -DBUILD_SHARED_LIBS=ON)
#   include/simdvol/*.hpp, include/simdvol/simdvol_shared.h
#                                                 (simdvol/simdvol.hpp includes
#                                                 the whole public API)
#   share/simdvol/kernels/*.cl, simdvol_shared.h  (the kernel sources, as
#                                                 embedded in the library)
#   share/doc/simdvol/KERNELS.md                  (the kernel ABI; the headers
#                                                 point to it)
#   lib/cmake/simdvol/simdvolConfig.cmake, ...ConfigVersion.cmake,
#     simdvolTargets.cmake, FindNiftiIO.cmake, FindTeemNrrd.cmake, FindGdcmLibs.cmake,
#     FindMetaIO.cmake, FindMinc.cmake
#   bin/simdvol                                   (the command-line program)
#   lib/simdvol/libsimdvol_oiio.so                (OpenImageIO, loaded by
#                                                 simdvol_core on first use)
# A consumer: find_package(simdvol) then target_link_libraries(app
# simdvol::simdvol) (the OpenCL layer; simdvol::core, the CPU library without
# OpenCL, comes with it). See examples/embed.
include(GNUInstallDirs)
include(CMakePackageConfigHelpers)

set(SIMDVOL_INSTALL_CMAKEDIR ${CMAKE_INSTALL_LIBDIR}/cmake/simdvol)
set(SIMDVOL_INSTALL_KERNELDIR ${CMAKE_INSTALL_DATADIR}/simdvol/kernels)
set(SIMDVOL_INSTALL_OIIO_MODULE
    ${CMAKE_INSTALL_LIBDIR}/simdvol/${CMAKE_SHARED_MODULE_PREFIX}simdvol_oiio${CMAKE_SHARED_MODULE_SUFFIX})

# Consumers compile the headers as C++20.
target_compile_features(simdvol_core PUBLIC cxx_std_20)
set_target_properties(simdvol_core PROPERTIES EXPORT_NAME core)
set_target_properties(simdvol_cl PROPERTIES EXPORT_NAME simdvol)
install(TARGETS simdvol_core simdvol_cl EXPORT simdvolTargets
  ARCHIVE DESTINATION ${CMAKE_INSTALL_LIBDIR}
  LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}
  RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR}
  INCLUDES DESTINATION ${CMAKE_INSTALL_INCLUDEDIR})
install(TARGETS simdvol RUNTIME DESTINATION ${CMAKE_INSTALL_BINDIR})
install(TARGETS simdvol_oiio LIBRARY DESTINATION ${CMAKE_INSTALL_LIBDIR}/simdvol)
if(BUILD_SHARED_LIBS)
  # The installed program finds the installed shared libraries.
  set_target_properties(simdvol PROPERTIES INSTALL_RPATH "\$ORIGIN/../${CMAKE_INSTALL_LIBDIR}")
endif()

# The public headers; simdvol_shared.h sits beside them (they include it as
# "simdvol_shared.h", found next to the including header).
file(GLOB SIMDVOL_PUBLIC_HEADERS CONFIGURE_DEPENDS
  ${PROJECT_SOURCE_DIR}/host/include/simdvol/*.hpp)
install(FILES ${SIMDVOL_PUBLIC_HEADERS} ${PROJECT_SOURCE_DIR}/kernels/simdvol_shared.h
  DESTINATION ${CMAKE_INSTALL_INCLUDEDIR}/simdvol)

# The kernel sources, for programs that build them themselves (another host
# language, their own OpenCL context): docs/KERNELS.md describes the ABI.
file(GLOB SIMDVOL_KERNEL_SOURCES CONFIGURE_DEPENDS
  ${PROJECT_SOURCE_DIR}/kernels/*.cl ${PROJECT_SOURCE_DIR}/kernels/*.h)
install(FILES ${SIMDVOL_KERNEL_SOURCES} DESTINATION ${SIMDVOL_INSTALL_KERNELDIR})
# That description, where simdvol.hpp and the kernels' users are pointed to
# (CMAKE_INSTALL_DOCDIR: share/doc/simdvol).
install(FILES ${PROJECT_SOURCE_DIR}/docs/KERNELS.md DESTINATION ${CMAKE_INSTALL_DOCDIR})

install(EXPORT simdvolTargets NAMESPACE simdvol:: DESTINATION ${SIMDVOL_INSTALL_CMAKEDIR})
get_target_property(SIMDVOL_CORE_TYPE simdvol_core TYPE)
configure_package_config_file(${PROJECT_SOURCE_DIR}/cmake/simdvolConfig.cmake.in
  ${PROJECT_BINARY_DIR}/simdvolConfig.cmake
  INSTALL_DESTINATION ${SIMDVOL_INSTALL_CMAKEDIR}
  PATH_VARS SIMDVOL_INSTALL_KERNELDIR SIMDVOL_INSTALL_OIIO_MODULE)
write_basic_package_version_file(${PROJECT_BINARY_DIR}/simdvolConfigVersion.cmake
  VERSION ${PROJECT_VERSION} COMPATIBILITY SameMinorVersion)
install(FILES
  ${PROJECT_BINARY_DIR}/simdvolConfig.cmake
  ${PROJECT_BINARY_DIR}/simdvolConfigVersion.cmake
  ${PROJECT_SOURCE_DIR}/cmake/FindNiftiIO.cmake
  ${PROJECT_SOURCE_DIR}/cmake/FindGdcmLibs.cmake
  ${PROJECT_SOURCE_DIR}/cmake/FindMetaIO.cmake
  ${PROJECT_SOURCE_DIR}/cmake/FindMinc.cmake
  ${PROJECT_SOURCE_DIR}/cmake/FindTeemNrrd.cmake
  ${PROJECT_SOURCE_DIR}/cmake/simdvol_oiio_module_path.cpp
  DESTINATION ${SIMDVOL_INSTALL_CMAKEDIR})
