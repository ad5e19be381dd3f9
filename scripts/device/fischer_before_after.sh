#!/usr/bin/env bash
# Fischer S1 (Franconia, close, looking down 63 degrees) and S3 (Pyrenees, far, 45 degrees)
# on the GPU machine: UDLOD before issue 18 (main at 3ab4290) against this build, flat (the
# old binary has no earth), `bench` at 1920x1080 (2 frames in flight, 300 frames after 20 of
# warm-up), two rounds alternated. The old binary preprocesses its own data sets there from
# the SRTM3 tiles (it cannot read today's manifests); this build, without GDAL there, reads
# the ones `vkterrain preprocess` wrote here (out/datasets/{franconia,pyrenees}, 27 MB each:
# one scene per carry, `SCENES=franconia` or `SCENES=pyrenees`). The same script runs here on
# lavapipe with `LOCAL=1 RES=640x360` (the lavapipe tests and benchmarks use, Mesa 25 from
# scripts/lavapipe.sh; `VKTERRAIN_LAVAPIPE=system` for the system's, not the carried loader). `EXTRA="KEY =
# VALUE"` adds a third run per round: this build with that line in its `[method]` table (e.g.
# `EXTRA="seed_tiles = 1"`, the prepass walking every level on the GPU).
#
# Here, before carrying: this build as .device-vk/vkterrain (prepare.sh, stripped), the old
# one built from 3ab4290 (`git worktree add ../before 3ab4290`, `cargo build --release
# --locked --bin vkterrain` there) stripped and copied to .device-vk/vkterrain-before, and
#   mkdir -p .device-vk/data/srtm .device-vk/data/datasets
#   cp ../shared/data/srtm/{N49E011,N50E011}.hgt.zip .device-vk/data/srtm/   (S1's tiles)
#   cp -r out/datasets/franconia .device-vk/data/datasets/
# Run there from the repository root:
#   bash scripts/device/fischer_before_after.sh > $OUT/fischer.txt 2>&1
set -u
if [ -z "${LOCAL:-}" ]; then
  . .device-vk/env.sh
else
  # Nothing to export with the system's lavapipe (a bare `export` would list the environment).
  lvp=$(scripts/lavapipe.sh)
  # shellcheck disable=SC2086 # NAME=VALUE words
  [ -z "$lvp" ] || export $lvp
fi
res=${RES:-1920x1080}
srtm=.device-vk/data/srtm
work=$(mktemp -d)
declare -A tiles=([franconia]="N49E011 N50E011" [pyrenees]="N41E001 N42E001")
declare -A scene=([franconia]=franconia_fischer_s1_flat_close_down63 [pyrenees]=pyrenees_fischer_s3_rough_far_down45)
for who in before after; do
  bin=.device-vk/vkterrain
  [ "$who" = before ] && bin=.device-vk/vkterrain-before
  mkdir -p "$work/$who/config/scenarios"
  for s in ${SCENES:-franconia pyrenees}; do
    cp "config/scenarios/${scene[$s]}.toml" "$work/$who/config/scenarios/"
    zips=$(for t in ${tiles[$s]}; do echo "$srtm/$t.hgt.zip"; done)
    mkdir -p "$work/$who/out/datasets"
    if [ "$who" = after ] && [ -d ".device-vk/data/datasets/$s" ]; then
      ln -s "$PWD/.device-vk/data/datasets/$s" "$work/$who/out/datasets/$s"
    else
      "$bin" preprocess $zips --out "$work/$who/out/datasets/$s" > /dev/null || exit 1
    fi
    printf '[dataset]\nkind = "tiles"\npath = "../out/datasets/%s"\n[scenario]\npath = "scenarios/%s.toml"\n[method]\nname = "udlod"\n' \
      "$s" "${scene[$s]}" > "$work/$who/config/$s.toml"
    if [ "$who" = after ] && [ -n "${EXTRA:-}" ]; then
      { cat "$work/$who/config/$s.toml"; echo "$EXTRA"; } > "$work/$who/config/$s-extra.toml"
    fi
  done
done
for s in ${SCENES:-franconia pyrenees}; do
  for round in 1 2; do
    for who in before after ${EXTRA:+extra}; do
      bin=.device-vk/vkterrain earth="--earth flat" cfg="$work/$who/config/$s.toml"
      [ "$who" = before ] && bin=.device-vk/vkterrain-before earth=""
      [ "$who" = extra ] && cfg="$work/after/config/$s-extra.toml"
      r=$("$bin" bench --config "$cfg" $earth --resolutions "$res" \
        --compare-frames-in-flight 2 --frames 300 --warmup 20 --out "$(mktemp -d)" 2>&1 |
        grep -E "$res   2|rror")
      echo "$s round $round $who${EXTRA:+ (extra: $EXTRA)}: $r"
    done
  done
done
rm -rf "$work"
