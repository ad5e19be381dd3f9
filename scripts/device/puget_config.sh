# Sourced by the device scripts: writes a config for the Puget Sound heights carried in
# .device-vk/data (no albedo: geometry only) to a temporary file and sets PUGET to its path.
PUGET=$(mktemp --suffix=.toml)
printf '[dataset]\nkind = "png16"\npath = "%s"\nspacing = 160.0\nvertical_scale = 0.1\n[scenario]\npath = "%s"\n' \
  "$PWD/.device-vk/data/ps_height_1k.png" "$PWD/config/scenarios/default.toml" > "$PUGET"
