# Shared by the load scripts: a small real map and a live `bowloc serve` on
# loopback. Source it from a script that has `cd`-ed to the repository root.
#
#   load_map                 builds data/load/{vocab.bowvoc,map.bowmap} from
#                            rtabmap-loop (K = 1000) on first use
#   start_server CONFIG LOG  starts the server, sets SERVER_PID and ADDR, waits
#                            until /readyz answers 200; stopped on exit
#   gardens_map K            builds data/gardens-K/ from gardens-point
#   server_config WORKERS QUEUE [EXTRA-TOML] [DIR]   a config for the map in
#                            DIR (default data/load)
#   rss_kib                  the server's resident memory in KiB

BIN=./target/release/bowloc
DATA=../shared/datasets/rtabmap-loop

load_map() {
  [ -x "$BIN" ] || cargo build --release
  mkdir -p data/load
  if [ ! -f data/load/map.bowmap ]; then
    $BIN --log warn vocab build --images $DATA/map.txt --words 1000 --seed 1 --out data/load/vocab.bowvoc
    $BIN --log warn map build --vocab data/load/vocab.bowvoc --images $DATA/map.txt --out data/load/map.bowmap
  fi
}

server_config() {
  cat <<TOML
[server]
listen = "127.0.0.1:0"
workers = $1
[files]
vocabulary = "${4:-data/load}/vocab.bowvoc"
map = "${4:-data/load}/map.bowmap"
[limits]
queue = $2
${3:-}
[bootstrap]
enabled = false
TOML
}

start_server() {
  $BIN serve --config "$1" >"$2" 2>&1 &
  SERVER_PID=$!
  trap 'kill $SERVER_PID 2>/dev/null; wait $SERVER_PID 2>/dev/null' EXIT
  ADDR=""
  for _ in $(seq 300); do
    ADDR=$(grep -o 'listening.*127\.0\.0\.1:[0-9]*' "$2" | grep -o '127\.0\.0\.1:[0-9]*' | head -1 || true)
    [ -n "$ADDR" ] && curl -sf "http://$ADDR/readyz" >/dev/null && return 0
    kill -0 $SERVER_PID 2>/dev/null || break
    sleep 0.1
  done
  cat "$2"
  echo "server did not start" >&2
  return 1
}

rss_kib() { awk '/VmRSS/ {print $2}' "/proc/$SERVER_PID/status"; }

# wrk_post_script FILE IMAGE [LIMIT]: a wrk Lua script posting IMAGE; with
# LIMIT, each wrk thread stops after LIMIT responses.
wrk_post_script() {
  cat >"$1" <<LUA
local f = io.open("$2", "rb")
wrk.method = "POST"
wrk.body = f:read("*all")
f:close()
wrk.headers["Content-Type"] = "image/jpeg"
local limit = ${3:-0}
local done = 0
function response(status, headers, body)
  done = done + 1
  if limit > 0 and done >= limit then wrk.thread:stop() end
end
LUA
}

# gardens_map K: builds data/gardens-K/{vocab.bowvoc,map.bowmap} from
# gardens-point's 200 map images (k-means seed 1) on first use.
gardens_map() {
  [ -x "$BIN" ] || cargo build --release
  local dir=data/gardens-$1 src=../shared/datasets/gardens-point
  mkdir -p "$dir"
  if [ ! -f "$dir/map.bowmap" ]; then
    $BIN --log warn vocab build --images $src/map.txt --words "$1" --seed 1 --out "$dir/vocab.bowvoc"
    $BIN --log warn map build --vocab "$dir/vocab.bowvoc" --images $src/map.txt --out "$dir/map.bowmap" --name gardens-point
  fi
}
