# The scenes the make-* scripts measure on besides the fixtures, so that every table uses
# the same ones: five randomized street scenes (seeds 7001-7005: neither the ground
# method's tuning seeds 1-6 nor its test seeds) and the shared real capture when present.
# Sourced (not run); needs $bin (the lidar-noise binary) and $out (a scratch folder).
random_seeds=(7001 7002 7003 7004 7005)

# Synthesizes one randomized scene (2 rotations) into $out/scenes/random-SEED/.
make_random_scene() {
  "$bin" --quiet synth --random "$1" --rotations 2 -o "$out/scenes/random-$1"
}

# Sets random (the captures of every randomized scene) and real (the shared capture, or
# none with a message).
make_scenes() {
  for seed in "${random_seeds[@]}"; do
    make_random_scene "$seed"
  done
  random=("$out"/scenes/random-*/*.pcap)
  real=()
  if [ -e ../shared/data/hdl32e/monterey.pcap ]; then
    real=(../shared/data/hdl32e/monterey.pcap)
  else
    echo "SKIPPED: ../shared/data is absent; the tables have no real-capture rows" >&2
  fi
}
