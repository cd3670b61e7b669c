#!/usr/bin/env bash
# Out-of-tree plugin build against an installed kelvin, as a plugin author does it.
# usage: sdk_plugin.sh <kelvin build dir> <kelvin source dir> <scratch dir>
set -euo pipefail
build=$1 src=$2 work=$3
rm -rf "$work" && mkdir -p "$work"
cmake --install "$build" --prefix "$work/prefix" >"$work/install.log"
cmake -S "$src/materials/plugin_example" -B "$work/plugin" -DCMAKE_PREFIX_PATH="$work/prefix" \
  -DCMAKE_BUILD_TYPE=Release >"$work/configure.log"
cmake --build "$work/plugin" >"$work/build.log"
plugin="$work/plugin/libyeoh_plugin.so"
kelvin="$work/prefix/bin/kelvin"

"$kelvin" check-material "$plugin" --set c2=2000

cat >"$work/yeoh-bar.yaml" <<YAML
name: yeoh-bar
mesh: { generate: box, lo: [0, 0, 0], hi: [0.1, 0.02, 0.02], element_size: 0.01 }
material:
  density: 1000
  elastic: { model: yeoh, plugin: $plugin, c1: 1.0e5, c2: 1.0e4, lambda: 2.0e5 }
  viscous: { model: newtonian, nu: 10 }
gravity: [0, 0, -9.81]
clamps:
  - { name: wall, select: { plane: { axis: x, at: 0 } } }
markers: { rest: [ { name: tip, at: [0.1, 0.01, 0.01] } ] }
time: { end: 0.1, output_rate: 100 }
YAML
"$kelvin" simulate "$work/yeoh-bar.yaml" -o "$work/out" -q
# The tip must have sagged under gravity (z below its rest height 0.01).
tip_z=$(tail -n 1 "$work/out/markers.csv" | cut -d, -f4)
awk -v z="$tip_z" 'BEGIN { if (!(z < 0.0099)) { print "tip did not sag: z = " z; exit 1 } }'
echo "sdk_plugin: out-of-tree plugin built, checked and simulated (tip z = $tip_z)"
