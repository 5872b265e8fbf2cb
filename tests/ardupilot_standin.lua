-- A stand-in of the ArduPilot scripting bindings the generated battery script uses, for
-- replaying recorded or simulated battery readings through it in a plain Lua 5.3.
--
-- usage: lua5.3 ardupilot_standin.lua SCRIPT.lua SAMPLES.txt
-- STANDIN_PARAMS="DL_RESERVE=60,..." in the environment sets parameter values.
-- SAMPLES: one call per line, "time_ms armed(0/1) voltage_V current_A consumed_mAh",
-- "nil" for a reading the battery monitor does not have. Prints what the script sends
-- ("F time_ms NAME value", "T time_ms severity text") and, at the end, the largest
-- instruction count of one call ("I n", counted in steps of HOOK_STEP) and the largest heap
-- after a full collection ("H kb", above the stand-in's own heap before the script loaded).

local HOOK_STEP = 10
local COLLECT_EVERY = 25

local script_path, samples_path = arg[1], arg[2]
local now_ms, armed, volts, amps, mah = 0, false, 0, nil, nil

local function reading(text)
  if text == "nil" then return nil end
  return tonumber(text)
end

-- parameter tables the script adds, and parameter values (from STANDIN_PARAMS)
local tables, values = {}, {}
for name, value in (os.getenv("STANDIN_PARAMS") or ""):gmatch("([%w_]+)=([%d%.%-]+)") do
  values[name] = tonumber(value)
end

local millis_meta = {__index = {tofloat = function(self) return self.ms end}}

local standin = {
  battery = {
    num_instances = function(_) return 1 end,
    voltage = function(_, _) return volts end,
    current_amps = function(_, _) return amps end,
    consumed_mah = function(_, _) return mah end,
  },
  arming = {is_armed = function(_) return armed end},
  gcs = {
    send_named_float = function(_, name, value)
      io.write(string.format("F %d %s %.6f\n", now_ms, name, value))
    end,
    send_text = function(_, severity, text)
      io.write(string.format("T %d %d %s\n", now_ms, severity, text))
    end,
  },
  param = {
    add_table = function(_, key, prefix, count)
      tables[key] = {prefix = prefix, count = count}
      return true
    end,
    add_param = function(_, key, index, name, default)
      local t = tables[key]
      if not t or index < 1 or index > t.count then return false end
      values[t.prefix .. name] = values[t.prefix .. name] or default
      return true
    end,
    get = function(_, name) return values[name] end,
  },
  millis = function() return setmetatable({ms = now_ms}, millis_meta) end,
}
for name, value in pairs(standin) do _G[name] = value end

local count = 0
local function hook() count = count + HOOK_STEP end

collectgarbage("collect")
local baseline = collectgarbage("count")

local chunk = assert(loadfile(script_path))
count = 0
debug.sethook(hook, "", HOOK_STEP)
local fn, interval = chunk()
chunk = nil  -- as ArduPilot keeps only the returned function
debug.sethook()
assert(type(fn) == "function" and type(interval) == "number", "script must return update, ms")
local max_count, max_heap = count, 0

local n = 0
for line in io.lines(samples_path) do
  local t, a, v, c, q = line:match("^(%S+) (%S+) (%S+) (%S+) (%S+)")
  if t then
    now_ms, armed, volts, amps, mah = tonumber(t), a == "1", reading(v), reading(c), reading(q)
    count = 0
    debug.sethook(hook, "", HOOK_STEP)
    local next_fn, next_interval = fn()
    debug.sethook()
    if count > max_count then max_count = count end
    assert(type(next_fn) == "function" and type(next_interval) == "number")
    fn = next_fn
    n = n + 1
    if n % COLLECT_EVERY == 0 then
      collectgarbage("collect")
      local heap = collectgarbage("count") - baseline
      if heap > max_heap then max_heap = heap end
    end
  end
end
collectgarbage("collect")
local heap = collectgarbage("count") - baseline
if heap > max_heap then max_heap = heap end
io.write(string.format("I %d\nH %.2f\nN %d\n", max_count, max_heap, n))
