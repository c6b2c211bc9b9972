# Shared by the scripts that drive a real `bowloc serve` on loopback
# (load.sh, overload.sh, replicas.sh, schemathesis.sh). Source it from the repository's
# root:  . scripts/lib/server.sh
#
#   load_map [SEED]          the rtabmap-loop map (K = 1000, vocabulary
#                            seed SEED, default 1) in data/load/ (seed 1)
#                            or data/load-sSEED/, built on first use
#   start_server CONFIG LOG [FLAG…]
#                            start the server (with these flags of `serve`),
#                            wait for /readyz; sets SERVER_PID and
#                            SERVER_ADDR (127.0.0.1:PORT). It starts as a
#                            server started for the first time (its learned
#                            plan runs its trials) unless
#                            BOWLOC_SEARCH__REMEMBER_PLAN=true is set: then
#                            it goes on from the plan an earlier one kept
#   stop_server              SIGTERM, then wait for it to exit
#   server_rss_kib           the server's resident memory in KiB
#   gardens_map K [SEED]     the gardens-point map (K words, vocabulary
#                            seed SEED, default 1) in data/gardens-K/ (seed
#                            1) or data/gardens-K-sSEED/, built on first use
#   dataset_map SRC K SEED BASE [NAME]
#                            the map of the dataset folder SRC (K words,
#                            vocabulary seed SEED, named NAME) in BASE
#                            (seed 1) or BASE-sSEED, built on first use
#   map_dir BASE SEED        where those maps are: BASE for seed 1, else
#                            BASE-sSEED
#   server_config WORKERS QUEUE [DIR] [EXTRA-TOML] [IMAGES]
#                            a loopback configuration for the map in DIR
#                            (default data/load), printed; thumbnails from
#                            IMAGES (default: the load map's dataset when
#                            DIR is not given, else none)
#   wrk_post_script FILE IMAGE   a wrk Lua script that posts IMAGE (JPEG)
#   load_prepare             for the wrk scripts: wrk present, the load map
#                            built, a temporary folder in TMP (removed, with
#                            the server stopped, on exit) holding post.lua,
#                            which posts LOAD_IMAGE (one of rtabmap-loop's
#                            queries)
#   median                   the median of the numbers on stdin

BOWLOC_BIN=./target/release/bowloc

# one number a line; of an even count, the upper middle one
median() { sort -g | awk '{v[NR] = $1} END {print v[int((NR + 1) / 2)]}'; }
DATASET=../shared/datasets/rtabmap-loop

map_dir() {
  if [ "$2" = 1 ]; then echo "$1"; else echo "$1-s$2"; fi
}

load_map() {
  dataset_map "$DATASET" 1000 "${1:-1}" data/load
}

start_server() {
  BOWLOC_SEARCH__REMEMBER_PLAN=${BOWLOC_SEARCH__REMEMBER_PLAN:-false} \
    "$BOWLOC_BIN" serve --config "$1" "${@:3}" >"$2" 2>&1 &
  SERVER_PID=$!
  SERVER_ADDR=""
  local _
  for _ in $(seq 100); do
    SERVER_ADDR=$(grep -o 'listening on http://127\.0\.0\.1:[0-9]*' "$2" | grep -o '127\.0\.0\.1:[0-9]*' | head -1 || true)
    [ -n "$SERVER_ADDR" ] && curl -sf "http://$SERVER_ADDR/readyz" >/dev/null && return 0
    kill -0 "$SERVER_PID" 2>/dev/null || break
    sleep 0.1
  done
  cat "$2" >&2
  echo "the server did not start" >&2
  return 1
}

stop_server() {
  [ -n "${SERVER_PID:-}" ] || return 0
  kill -TERM "$SERVER_PID" 2>/dev/null
  wait "$SERVER_PID" 2>/dev/null
  SERVER_PID=""
}

server_rss_kib() {
  awk '/VmRSS/ {print $2}' "/proc/$SERVER_PID/status"
}

gardens_map() {
  dataset_map ../shared/datasets/gardens-point "$1" "${2:-1}" "data/gardens-$1" gardens-point
}

dataset_map() {
  [ -x "$BOWLOC_BIN" ] || cargo build --release
  local src=$1 words=$2 seed=$3 dir
  dir=$(map_dir "$4" "$seed")
  mkdir -p "$dir"
  if [ ! -f "$dir/map.bowmap" ]; then
    "$BOWLOC_BIN" --log warn vocab build --images "$src/map.txt" --words "$words" --seed "$seed" \
      --out "$dir/vocab.bowvoc"
    "$BOWLOC_BIN" --log warn map build --vocab "$dir/vocab.bowvoc" --images "$src/map.txt" \
      --out "$dir/map.bowmap" ${5:+--name "$5"}
  fi
}

server_config() {
  cat <<TOML
[server]
listen = "127.0.0.1:0"
workers = $1
[files]
vocabulary = "${3:-data/load}/vocab.bowvoc"
map = "${3:-data/load}/map.bowmap"
# the map's images (thumbnails): the load map's, unless told otherwise
images = "${5-$([ -z "${3:-}" ] && echo "$DATASET")}"
[limits]
queue = $2
${4:-}
[bootstrap]
enabled = false
TOML
}

wrk_post_script() {
  cat >"$1" <<LUA
local f = io.open("$2", "rb")
wrk.method = "POST"
wrk.body = f:read("*all")
f:close()
wrk.headers["Content-Type"] = "image/jpeg"
LUA
}

LOAD_IMAGE=$DATASET/images/50.jpg

load_prepare() {
  command -v wrk >/dev/null || { echo "wrk missing: apt-get install wrk" >&2; exit 1; }
  load_map
  TMP=$(mktemp -d)
  trap 'stop_server; rm -rf "$TMP"' EXIT
  wrk_post_script "$TMP/post.lua" "$LOAD_IMAGE"
}
