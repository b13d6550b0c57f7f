-- mix.lua: the request mix of the soak (scripts/soak), for wrk: renders (GET and POST),
-- map tiles, picks, preloads, evictions and heights edits through the admin API, in a
-- fixed rotation offset per connection. Each thread counts answers by status, 503s
-- without Retry-After, and anything outside the allowed set; done() prints one JSON line
-- for scripts/soak.
local token = os.getenv("TERRAD_ADMIN_TOKEN") or ""
local json = {["Content-Type"] = "application/json"}
local admin = {["Content-Type"] = "application/json", ["Authorization"] = "Bearer " .. token}
local reqs = {}
local function add(method, path, headers, body)
  reqs[#reqs + 1] = wrk.format(method, path, headers, body)
end
for k = 0, 5 do
  add("GET", string.format("/v1/render?dataset=levi&camera.position.x=%d&camera.position.y=-2000" ..
      "&camera.position.z=1500&camera.pitch=-15&image.width=160&image.height=120", 3000 + 200 * k))
  add("POST", "/v1/render", json, string.format('{"dataset":"volcano","camera":{"position":' ..
      '{"x":%d,"y":-400,"z":450},"pitch":-20},"image":{"width":128,"height":96},' ..
      '"effects":{"shadows":true}}', 200 + 20 * k))
  local tile = ({"0/0/0", "1/0/0", "1/1/0", "1/0/1", "2/1/1", "2/2/2"})[k + 1] -- all over data
  add("GET", "/v1/tiles/trinidad/" .. tile .. ".png")
  add("POST", "/v1/pick", json, string.format('{"dataset":"trinidad","camera":{"position":' ..
      '{"x":20000,"y":-2000,"z":5500},"pitch":-15},"pick":[[%d,240],[0,0]]}', 100 + k))
  add("GET", "/healthz")
end
add("POST", "/v1/admin/preload", admin, '{"dataset":"volcano","build":["maxmip","planes"],"rebuild":true}')
add("DELETE", "/v1/admin/datasets/volcano/tiles", admin)
add("POST", "/v1/admin/preload", admin, '{"dataset":"trinidad","build":["planes"]}')
-- a 4 x 4 patch of volcano raised to 1000 m, then to 1010 m (little-endian float32; wrk's
-- LuaJIT has no string.pack): each edit is a new version and a rebuild job
local octets = {["Content-Type"] = "application/octet-stream", ["Authorization"] = "Bearer " .. token}
for _, f in ipairs({string.char(0, 0, 0x7A, 0x44), string.char(0, 0x80, 0x7C, 0x44)}) do
  add("PUT", "/v1/admin/datasets/volcano/heights?x=10&y=10&w=4&h=4", octets, string.rep(f, 16))
end

local threads = {}
function setup(thread)
  table.insert(threads, thread)
end

function init(args)
  codes = {}
  bad = 0
  no_retry = 0
  i = math.random(#reqs)
end

function request()
  i = i % #reqs + 1
  return reqs[i]
end

local allowed = {[200] = true, [202] = true, [304] = true, [503] = true}

function response(status, headers, body)
  codes[status] = (codes[status] or 0) + 1
  if not allowed[status] then bad = bad + 1 end
  if status == 503 and not headers["Retry-After"] then no_retry = no_retry + 1 end
end

function done(summary, latency, requests)
  local all, nbad, nretry = {}, 0, 0
  for _, t in ipairs(threads) do
    for code, n in pairs(t:get("codes")) do all[code] = (all[code] or 0) + n end
    nbad = nbad + t:get("bad")
    nretry = nretry + t:get("no_retry")
  end
  local parts = {}
  for code, n in pairs(all) do parts[#parts + 1] = string.format('"%d": %d', code, n) end
  io.write(string.format('SOAK {"requests": %d, "errors": {"connect": %d, "read": %d, "write": %d, ' ..
    '"timeout": %d}, "codes": {%s}, "unexpected": %d, "503_without_retry_after": %d, ' ..
    '"p50_ms": %.2f, "p99_ms": %.2f, "seconds": %.1f}\n',
    summary.requests, summary.errors.connect, summary.errors.read, summary.errors.write,
    summary.errors.timeout, table.concat(parts, ", "), nbad, nretry,
    latency:percentile(50) / 1000, latency:percentile(99) / 1000, summary.duration / 1e6))
end
