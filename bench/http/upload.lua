-- wrk script: POST the mesh in $VX_BENCH_MESH with a unique comment line
-- per request, so every upload is a new mesh (hashed, parsed, stored).
local f = assert(io.open(os.getenv("VX_BENCH_MESH"), "rb"))
local mesh = f:read("*a")
f:close()
local dedup = os.getenv("VX_BENCH_DEDUP") == "1"
local n = 0
local tid = 0
setup = function(thread)
  thread:set("tid", tid)
  tid = tid + 1
end
request = function()
  n = n + 1
  local body = mesh
  if not dedup then body = "# " .. tid .. "-" .. n .. "\n" .. mesh end
  return wrk.format("POST", "/v1/meshes", {["Content-Type"] = "model/obj"}, body)
end
done = function(summary, latency, requests)
  io.write(string.format("BYTES_PER_REQ %d\n", #mesh))
end
