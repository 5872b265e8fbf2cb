@HEADER@
--
-- Reads battery:voltage, current_amps, consumed_mah (instance BATT_INSTANCE below), sends
-- named floats DL_TREM [s] and DL_SOC [%] once a second and warns once at each reserve.
-- Tables: charge taken out Q [Ah]; pack currents I [A]; OCV [V] the model's rest voltage
-- at Q; REM[k][j] charge left to the cutoff [Ah] from Q[k] at I[j]; VL[k][j] the loaded
-- pack voltage [V] at Q[k] and I[j]. Lua 5.3.

local BATT_INSTANCE = @INSTANCE@
local RESERVE_S = @RESERVE_S@

-- settings DL_BATT_IDX and DL_RESERVE (parameter table key PARAM_KEY; the values above are
-- their defaults and stay in use when the table cannot be added)
local PARAM_KEY = @PARAM_KEY@
if param:add_table(PARAM_KEY, "DL_", 2) then
  param:add_param(PARAM_KEY, 1, "BATT_IDX", BATT_INSTANCE)
  param:add_param(PARAM_KEY, 2, "RESERVE", RESERVE_S)
  BATT_INSTANCE = math.floor(param:get("DL_BATT_IDX") or BATT_INSTANCE)
  RESERVE_S = param:get("DL_RESERVE") or RESERVE_S
end
local INTERVAL_MS = @INTERVAL_MS@
local SEND_MS = @SEND_MS@
local WINDOW_S = @WINDOW_S@
local CAPACITY_AH = @CAPACITY_AH@
local REF_A = @REF_A@
local REST_A = @REST_A@
local FILTER_S = @FILTER_S@

local Q = @Q@
local I = @I@
local OCV = @OCV@
local REM = @REM@
local VL = @VL@

local NQ = #Q
local NI = #I

-- segment of a sorted grid holding x (clamped) and the fraction along it
local function seg(x, grid, n)
  if x <= grid[1] then return 1, 0 end
  if x >= grid[n] then return n - 1, 1 end
  local k = 1
  while grid[k + 1] < x do k = k + 1 end
  return k, (x - grid[k]) / (grid[k + 1] - grid[k])
end

-- value of a Q x I table at charge q [Ah] and current a [A] (Q evenly spaced from 0)
local DQ = Q[2] - Q[1]
local function at(tab, q, a)
  local k, f
  if q <= 0 then
    k, f = 1, 0
  elseif q >= Q[NQ] then
    k, f = NQ - 1, 1
  else
    k = math.floor(q / DQ) + 1
    if k > NQ - 1 then k = NQ - 1 end
    f = (q - Q[k]) / DQ
  end
  local j, g = seg(a, I, NI)
  local r0, r1 = tab[k], tab[k + 1]
  local lo = r0[j] + g * (r0[j + 1] - r0[j])
  local hi = r1[j] + g * (r1[j + 1] - r1[j])
  return lo + f * (hi - lo)
end

-- charge taken out [Ah] at which the voltage falls to v: the rest voltage (a == nil)
-- or the loaded voltage at current a [A]; both fall with the charge
local function charge_at(v, a)
  local j, g = 1, 0
  if a then j, g = seg(a, I, NI) end
  local prev
  for k = 1, NQ do
    local row = a and VL[k] or nil
    local vk = a and (row[j] + g * (row[j + 1] - row[j])) or OCV[k]
    if vk <= v then
      if k == 1 or prev == vk then return Q[k] end
      return Q[k - 1] + (prev - v) / (prev - vk) * (Q[k] - Q[k - 1])
    end
    prev = vk
  end
  return Q[NQ]
end

-- seconds to the cutoff from charge q0 [Ah] at the mean current a [A] with peaks of
-- peak [A]: the pack is empty when the loaded voltage at the peak reaches the cutoff
-- (REM at the peak current falls to 0); charge drawn at the mean. With gamma > 0 the
-- mean current grows as the voltage falls, I ~ V^-gamma (1 = constant power), marched
-- over the charge left in STEPS steps.
local STEPS = 12
local function time_left(q0, a, peak, gamma)
  if a < I[1] * 0.01 then a = I[1] * 0.01 end
  local ratio = peak > a and peak / a or 1
  local span = at(REM, q0, ratio * a)
  if span <= 0 then return 0 end
  if gamma < 0.02 then return span * 3600 / a end
  local v0 = at(VL, q0, a)
  local dq = span / STEPS
  local t, qk, ik, left = 0, q0, a, span
  for _ = 1, STEPS + 4 do
    local qn = qk + dq
    local inew = ik
    inew = a * (v0 / at(VL, qn, inew)) ^ gamma
    local after = at(REM, qn, ratio * inew)
    local mean = 0.5 * (ik + inew)
    if after <= 0 then
      return t + left / (left - after) * dq * 3600 / mean
    end
    t = t + dq * 3600 / mean
    qk, ik, left = qn, inew, after
  end
  return t + left * 3600 / ik
end

local q_rest = nil      -- charge taken out at rest before take-off [Ah]
local q = 0             -- charge taken out now [Ah]
local was_armed = false
local base_mah = nil    -- consumed_mah at arming
local counted = 0       -- charge integrated from current_amps since arming [Ah]
local last_ms = nil
local next_send = 0
local v_filt = nil
local warned_reserve, warned_last, said_no_current = false, false, false
-- ring of (time [s], charge [Ah], voltage [V]) once a second over the last WINDOW_S
local RING = WINDOW_S + 1
local ring_t, ring_q, ring_v, ring_n, ring_head, next_ring = {}, {}, {}, 0, 0, 0
local peak_a = 0        -- highest 1 s mean current in the ring [A]
local mean_v = 0        -- mean voltage over the ring [V]
local ref_a, ref_v = nil, nil   -- mean current and voltage of the first full window
local gamma = 0         -- load exponent: I ~ V^-gamma (0 constant current, 1 power)
local g_filt = 0        -- its estimate, filtered over GAMMA_S seconds
local GAMMA_S = 20

local function ring_push(t, charge, v)
  ring_head = ring_head % RING + 1
  ring_t[ring_head], ring_q[ring_head], ring_v[ring_head] = t, charge, v
  if ring_n < RING then ring_n = ring_n + 1 end
  local k = ring_head
  local sum_v, top = v, 0
  for _ = 2, ring_n do
    local prev = (k - 2) % RING + 1
    local dt = ring_t[k] - ring_t[prev]
    if dt > 0 then
      local amps = (ring_q[k] - ring_q[prev]) * 3600 / dt
      if amps > top then top = amps end
    end
    sum_v = sum_v + ring_v[prev]
    k = prev
  end
  peak_a, mean_v = top, sum_v / ring_n
end

-- mean current [A] over the ring (nil before two entries)
local function recent_current(t, charge)
  if ring_n < 2 then return nil end
  local oldest = (ring_head - ring_n) % RING + 1
  local dt = t - ring_t[oldest]
  if dt <= 0 then return nil end
  return (charge - ring_q[oldest]) * 3600 / dt
end

-- how the mean current follows the voltage since the first full window
local function follow_load(a)
  if ring_n < RING or a <= REST_A then return end
  if ref_a == nil then
    ref_a, ref_v = a, mean_v
  elseif ref_v / mean_v > 1.005 then
    local g = math.log(a / ref_a) / math.log(ref_v / mean_v)
    if g < -1 then g = -1 elseif g > 2 then g = 2 end
    g_filt = g_filt + (g - g_filt) / GAMMA_S        -- once a second
    gamma = g_filt < 0 and 0 or (g_filt > 1.2 and 1.2 or g_filt)
  end
end

local function send(trem, soc)
  gcs:send_named_float("DL_TREM", trem)
  gcs:send_named_float("DL_SOC", soc)
end

local function warn(trem)
  if not warned_reserve and trem <= RESERVE_S then
    warned_reserve = true
    gcs:send_text(4, string.format("DL: %.0f s of flight left to the cutoff", trem))
  end
  if not warned_last and trem <= RESERVE_S / 3 then
    warned_last = true
    gcs:send_text(2, string.format("DL: %.0f s left, land now", trem))
  end
end

local function update()
  if battery:num_instances() <= BATT_INSTANCE then
    return update, 1000
  end
  local now = millis():tofloat()
  local t = now * 0.001
  local v = battery:voltage(BATT_INSTANCE)
  local amps = battery:current_amps(BATT_INSTANCE)
  local mah = battery:consumed_mah(BATT_INSTANCE)
  local dt = last_ms and (now - last_ms) * 0.001 or 0
  last_ms = now
  if not v or v <= 0 then return update, INTERVAL_MS end
  local alpha = dt / (FILTER_S + dt)
  v_filt = v_filt and (v_filt + alpha * (v - v_filt)) or v
  local armed = arming:is_armed()
  if not armed then
    was_armed = false
    if amps == nil or amps < REST_A then
      q_rest = charge_at(v_filt, nil)
      q = q_rest
    end
    if now >= next_send then
      next_send = now + SEND_MS
      gcs:send_named_float("DL_SOC", 100 * (1 - q / CAPACITY_AH))
    end
    return update, INTERVAL_MS
  end
  if not was_armed then   -- take-off: count from the rest reading
    was_armed = true
    if q_rest == nil then q_rest = charge_at(v, amps or REF_A) end
    base_mah, counted, ring_n, next_ring = mah, 0, 0, 0
    ref_a, ref_v, gamma, g_filt, peak_a = nil, nil, 0, 0, 0
    warned_reserve, warned_last = false, false
  end
  local load
  if amps == nil then       -- no current sensor: the filtered voltage alone
    if not said_no_current then
      said_no_current = true
      gcs:send_text(4, string.format("DL: no current sensor, time left from voltage at %.1f A",
                                     REF_A))
    end
    local qv = charge_at(v_filt, REF_A)
    if qv > q then q = qv end
    load = REF_A
  else
    counted = counted + amps * dt / 3600
    if mah ~= nil and base_mah ~= nil then
      q = q_rest + (mah - base_mah) * 0.001
    else
      q = q_rest + counted
    end
    -- the recent load from the integrated current: a charge counter may update slowly
    load = recent_current(t, counted) or amps
    if t >= next_ring then
      next_ring = t + 1
      ring_push(t, counted, v)
      load = recent_current(t, counted) or amps
      follow_load(load)
    end
  end
  if now >= next_send then
    next_send = now + SEND_MS
    local soc = 100 * (1 - q / CAPACITY_AH)
    if load > REST_A then
      local trem = time_left(q, load, amps and peak_a or load, amps and gamma or 0)
      send(trem, soc)
      warn(trem)
    else
      gcs:send_named_float("DL_SOC", soc)
    end
  end
  return update, INTERVAL_MS
end

return update, INTERVAL_MS
