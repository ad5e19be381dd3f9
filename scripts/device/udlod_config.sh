# Sourced by the UDLOD A/B scripts (scripts/device/udlod_binaries_ab.sh,
# scripts/udlod_binaries_ab_lavapipe.sh): `udlod_config BASE [LINES]` writes a copy of config
# BASE with UDLOD as its method plus LINES (printf %b escapes), its scenario path absolute, to a
# temporary file and prints the file's path.
udlod_config() {
  local cfg
  cfg=$(mktemp --suffix=.toml)
  sed "s#\"scenarios/default.toml\"#\"$PWD/config/scenarios/default.toml\"#" "$1" > "$cfg"
  if grep -q '^\[method\]' "$cfg"; then sed -i '/^\[method\]/,/^$/d' "$cfg"; fi
  printf '\n[method]\nname = "udlod"\n%b\n' "${2:-}" >> "$cfg"
  echo "$cfg"
}
