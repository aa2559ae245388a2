// Installed beside simdvolConfig.cmake, which adds it to simdvol::core's
// INTERFACE_SOURCES where the library is static: compiled into the program
// that links it, it tells the library where this installed package keeps
// its OpenImageIO module (lib/simdvol/libsimdvol_oiio.so). A static library
// cannot find that place from its own; the program may live anywhere.
// Weak, so that several targets of one program may each carry it.
extern "C" __attribute__((weak)) const char* simdvol_installed_oiio_module() {
  return SIMDVOL_INSTALLED_OIIO_MODULE;
}
