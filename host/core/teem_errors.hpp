// teem's error stack (biff) as one readable line; private to simdvol_core
// (io.cpp's NRRD loader, image.cpp's PNG writer).
#pragma once

#include <string>

namespace simdvol::detail {

/// biffGetDone(key) with its lines joined by ';' and trailing blanks cut;
/// "unknown teem error" when the stack is empty.
std::string biff_message(const char* key);

}  // namespace simdvol::detail
