// `simdvol mismatch`: the multi-pass shear rotation against the minimum
// mismatch mapping (thesis 5.3.4, 5.4, 5.7), with operation counts.
#pragma once

#include <ostream>

namespace CLI {
class App;
}

namespace simdvol {

/// Adds the `mismatch` subcommand (its options live in mismatch_cmd.cpp).
CLI::App* add_mismatch_command(CLI::App& app);

/// Runs it after parsing; returns the exit code. Throws simdvol::Error on bad
/// arguments or unwritable outputs.
int run_mismatch_command(std::ostream& os);

}  // namespace simdvol
