# Sourced by the scripts (not run): their --help and their refusal of
# arguments they do not take, in one place.
#   script_help          prints the calling script's header comment
#   no_arguments NAME "$@"
#                        --help: the header, exit 0; any argument: refused
#                        with exit 2, naming it, before the script does
#                        anything
script_help() {
  awk 'NR > 1 && /^#/ { sub(/^# ?/, ""); print; next } NR > 1 { exit }' "$0"
}
no_arguments() {
  local name=$1
  shift
  case "${1:-}" in
    "") ;;
    -h | --help) script_help; exit 0 ;;
    *) echo "$name: takes no arguments, not '$1' (--help says what it does)" >&2; exit 2 ;;
  esac
}
