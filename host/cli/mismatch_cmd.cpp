// `simdvol mismatch` (see mismatch_cmd.hpp).
#include "mismatch_cmd.hpp"

#include <CLI/CLI.hpp>

namespace simdvol {

CLI::App* add_mismatch_command(CLI::App& app) {
  return app.add_subcommand("mismatch",
                            "shear rotation vs minimum-mismatch mapping: mismatch and op counts");
}

int run_mismatch_command(std::ostream& os) {
  os << "mismatch: not implemented yet\n";
  return 0;
}

}  // namespace simdvol
