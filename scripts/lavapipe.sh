#!/usr/bin/env bash
# Prints the environment (VKTERRAIN_LAVAPIPE=25 VK_ICD_FILENAMES=... LD_LIBRARY_PATH=...)
# under which `make test` and the CI benchmarks run on lavapipe from Mesa 25.0.7, or nothing
# when the system's Mesa is new enough (>= 24) or VKTERRAIN_LAVAPIPE=system asks for it.
#
# Why (docs/architecture.md, "Which lavapipe"): Debian 12 ships Mesa 22.3, whose lavapipe has
# no VK_EXT_mesh_shader and renders the methods about 2x slower than Mesa 25.0 from
# bookworm-backports. Installing the backport system-wide would replace the machine's Mesa for
# every program, so on Debian 12 this script downloads the pinned packages with apt-get (the
# package registry; its own lists directory, nothing installed) and unpacks them into
# target/lavapipe-25 once. Elsewhere (Ubuntu 24.04 ships Mesa 24) the system's driver is used.
set -euo pipefail
cd "$(dirname "$0")/.."
[ "${VKTERRAIN_LAVAPIPE:-25}" = system ] && exit 0

# Pinned: the versions the tests were last run with (2026-11-30).
MESA=25.0.7-2~bpo12+1
DRM=2.4.123-1~bpo12+1
DIR=${VKTERRAIN_LAVAPIPE_DIR:-$PWD/target/lavapipe-25}
LIB=$DIR/root/usr/lib/x86_64-linux-gnu
ICD=$DIR/lvp_icd.json

emit() { echo "VKTERRAIN_LAVAPIPE=25 VK_ICD_FILENAMES=$ICD LD_LIBRARY_PATH=$LIB${LD_LIBRARY_PATH:+:$LD_LIBRARY_PATH}"; }
[ -f "$ICD" ] && [ -f "$LIB/libvulkan_lvp.so" ] && { emit; exit 0; }

installed=$(dpkg-query -W -f='${Version}' mesa-vulkan-drivers 2>/dev/null || true)
codename=$(. /etc/os-release 2>/dev/null && echo "${VERSION_CODENAME:-}")
if [ "$codename" != bookworm ] || [ "$(uname -m)" != x86_64 ] \
    || dpkg --compare-versions "${installed:-0}" ge 24; then
    echo "lavapipe: the system's Mesa ${installed:-(not installed)} on ${codename:-unknown}" >&2
    exit 0
fi

echo "lavapipe: fetching mesa-vulkan-drivers $MESA from bookworm-backports into $DIR" >&2
rm -rf "$DIR.partial"
mkdir -p "$DIR.partial/lists/partial" "$DIR.partial/cache/archives/partial" "$DIR.partial/debs"
printf 'deb [signed-by=/usr/share/keyrings/debian-archive-keyring.gpg] http://deb.debian.org/debian bookworm-backports main\n' \
    >"$DIR.partial/sources.list"
apt_opts=(-o "Dir::Etc::SourceList=$DIR.partial/sources.list" -o Dir::Etc::SourceParts=/dev/null
    -o "Dir::State::Lists=$DIR.partial/lists" -o "Dir::Cache=$DIR.partial/cache"
    -o APT::Sandbox::User=root -qq)
apt-get "${apt_opts[@]}" update >&2 \
    || { echo "error: lavapipe: apt-get update of bookworm-backports failed (set VKTERRAIN_LAVAPIPE=system to use Mesa $installed)" >&2; exit 1; }
(cd "$DIR.partial/debs" && apt-get "${apt_opts[@]}" download \
    "mesa-vulkan-drivers=$MESA" "libdrm2=$DRM" "libdrm-amdgpu1=$DRM" >&2) \
    || { echo "error: lavapipe: mesa-vulkan-drivers=$MESA or libdrm $DRM is not in bookworm-backports any more: update the pins in scripts/lavapipe.sh" >&2; exit 1; }
for deb in "$DIR.partial"/debs/*.deb; do dpkg-deb -x "$deb" "$DIR.partial/root"; done
lvp=$DIR/root/usr/lib/x86_64-linux-gnu/libvulkan_lvp.so
printf '{"file_format_version": "1.0.0", "ICD": {"library_path": "%s", "api_version": "1.4.305"}}\n' "$lvp" \
    >"$DIR.partial/lvp_icd.json"
rm -rf "$DIR.partial/lists" "$DIR.partial/cache" "$DIR.partial/debs" "$DIR"
mv "$DIR.partial" "$DIR"
emit
