// fwref/profile.hpp -- scope: the channel profiles of core/profiles.py on one raw sample, in
// float32, as the streaming runtime (fwref/stream.hpp) applies them. Header-only, no heap.
//
// The profiles (enum Profile, their ids), their stream channels and model channels come from
// fwref/channels_gen.hpp, generated from core/channels.py's tables: a stream delivers the raw
// channels the on-board record names (formats/onboard.py), for the profiles with a hover estimate
// the profile's raw channels then ``airborne`` (0/1) last, for ``paper`` the model's own channels.
// This file reads a hover profile's raw columns by position: roll pitch p q r vx vy yaw vz V_b first
// (the generator refuses a profile that does not start so), the current at ``i_b``, thr1..4 and
// vib_px4 from ``thr``, the ESC block from ``rpm``. The model channels, as Python:
//   roll pitch p q r | vx_h = c vx + s vy | vy_h = -s vx + c vy | vz | v_cell = V_b / cells |
//   i_rel = I_b / hover_cur (min, esc) | m1..4_rel = thr / hover_cmd | vib = vib_px4 |
//   (esc only) rpmk_rel = rpmk / ((((rpm1 + rpm2) + rpm3) + rpm4) * 0.25f), esck_i_rel likewise over esc_cur1..4,
//   esck_t_rel = esc_tempk - ((((esc_temp1 + esc_temp2) + esc_temp3) + esc_temp4) * 0.25f)
// with c = float(cos(double(yaw))), s = float(sin(double(yaw))) (libm, correctly rounded; core/profiles.py
// does the same), every other operation one float32 operation. ``prep`` computes a sample's values
// that do not depend on the hover estimate (at push); ``hover`` divides the hover columns once the
// estimate exists (at the decision): thr / cmd is the same float32 division either way.
//
// The masked profile (``flightlog-mask``, ProfileSpec::groups > 0) reads vib_ap too (``vib_ap``, a model
// channel after vib) and takes an availability mask ``avail`` (bit g: the flight has group g of
// kGroupNames; ``profile_available`` forms it from the columns a stream carries): a lacking group's
// model channels take their fills (ProfileSpec::fill), its availability channel 0 (1 when present),
// an absent pitch enters the hover estimate as 0 (level) and an absent current as NaN
// (``hover_inputs``). The fills replace whatever the absent columns hold, so those may be NaN.
//
// The reference profile (``flightlog-ref``, ProfileSpec::ref >= 0) is the masked one plus ten channels
// relative to the vehicle record (fwref/vehicle_record.hpp, its arithmetic there) and ``avail_reference``
// (1 when the record's first share is finite, else 0). ``vehicle`` null: every reference channel at its
// fill; a field the record does not hold (NaN): that channel at its fill (each channel by its own fields,
// as core/profiles.py); a group the flight lacks: its reference channels at their fills too. ``prep`` puts
// each motor's expected share s_k in the m{k}_ref column, ``hover`` divides m{k}_rel by it: the same
// float32 division as core/vehicle_record.py.
//
// The physics profile (``flightlog-phys``, ProfileSpec::phys >= 0) is the reference one plus eight channels
// computed by recursions over the flight so far (fwref/causal.hpp; core/causal.py): ``r_cell`` =
// sag(v_cell, I_b), ``r_cell_ref`` = r_cell - the record's sag, ``m{k}_ref_lp`` = ewma(thr_k / s_k) / hover_cmd
// (``prep`` steps the recursion, ``hover`` divides), ``vib_ref_lp``, ``vib_ap_ref_lp`` = ewma of the vibration
// excesses. They need the flight's PhysState (``phys``; null: NaN, the samples undecided); a channel whose
// record field is not held takes its fill (a smoothed deviation's input is then NaN: the state does not move);
// r_cell and r_cell_ref need the battery and the current groups.
#pragma once

#include <cmath>
#include <cstdint>
#include <cstring>

#include "fwref/causal.hpp"
#include "fwref/channels_gen.hpp"  // Profile, ProfileSpec and the profiles' channel lists, from core/channels.py
#include "fwref/vehicle_record.hpp"

namespace fwref {

inline const ProfileSpec& profile_spec(Profile p) { return profile_tables::kSpecs[static_cast<int>(p)]; }

constexpr std::uint32_t kAllGroups = (1u << kGroupCount) - 1u;  // an availability mask with every group
constexpr std::uint64_t kAllCarried = ~std::uint64_t(0);       // a stream carrying every column

// Raw column ``col`` is present under availability mask ``avail`` (a column outside every group always is).
inline bool column_present(const ProfileSpec& s, std::uint32_t avail, int col) {
  return s.groups == 0 || s.raw_group[col] < 0 || ((avail >> s.raw_group[col]) & 1u) != 0;
}

// The availability mask of a stream carrying the columns ``carried`` (bit r: raw column r, r < 64): a
// group is available when every column of it is carried. False when the profile cannot run the
// stream: a profile without a mask lacking a column, or the masked profile lacking its minimum (a
// column outside every group, airborne included).
inline bool profile_available(Profile p, int raw_n, std::uint64_t carried, std::uint32_t* avail) {
  const ProfileSpec& s = profile_spec(p);
  *avail = kAllGroups;
  for (int r = 0; r < raw_n && r < 64; ++r) {
    if ((carried >> r) & 1u) continue;
    if (s.groups == 0 || s.raw_group[r] < 0) return false;
    *avail &= ~(1u << s.raw_group[r]);
  }
  return true;
}

// The inputs of the hover estimate (fwref/hover.hpp) in one raw sample of a hover profile.
struct HoverInputs {
  float vz, roll, pitch, thr[4], current;
  bool airborne;
};

inline HoverInputs hover_inputs(Profile p, const float* raw, std::uint32_t avail = kAllGroups) {
  const ProfileSpec& s = profile_spec(p);
  const float pitch = column_present(s, avail, 1) ? raw[1] : 0.0f;  // an absent pitch: level (core/hover.py)
  const float current = s.i_b >= 0 && column_present(s, avail, s.i_b) ? raw[s.i_b] : NAN;
  HoverInputs h{raw[8], raw[0], pitch, {raw[s.thr], raw[s.thr + 1], raw[s.thr + 2], raw[s.thr + 3]},
                current, raw[s.raw - 1] >= 0.5f};  // NaN airborne: not airborne
  return h;
}

// The reference channels of a prepared sample x (before the group fills): s_k in the m{k}_ref columns
// (profile_hover divides), the vibration excesses, the rpm shares over the record's; a channel the record
// does not hold at its fill. vx_h and r enter as 0 when the flight lacks vel_h / rates.
inline void reference_prep(const ProfileSpec& s, const float* raw, std::uint32_t avail, const VehicleRecord* vehicle,
                           int rpm_rel, float* x) {
  float* ref = x + s.ref;
  const bool rec = vehicle != nullptr;
  if (rec) {
    const VehicleRecord& v = *vehicle;
    const float vx = ((avail >> kGroupVelH) & 1u) != 0 ? x[5] : 0.0f;
    const float r = ((avail >> kGroupRates) & 1u) != 0 ? x[4] : 0.0f;
    for (int k = 0; k < 4; ++k) ref[k] = expected_share(v, k, vx, r);
    const float* t = raw + s.thr;
    const float c = (((t[0] + t[1]) + t[2]) + t[3]) * 0.25f;  // core.hover's collective
    ref[4] = vibration_excess(v, vehicle::kVibFloor, t[4], c);
    ref[5] = vibration_excess(v, vehicle::kVibApFloor, raw[s.vib_ap], c);
    for (int k = 0; k < 4; ++k) ref[6 + k] = x[rpm_rel + k] / v.v[vehicle::kRpmShare + k];
  }
  for (int j = 0; j < 10; ++j) {
    if (!rec || !reference_held(*vehicle, j)) ref[j] = s.fill[s.ref + j];
  }
}

// The physics channels of a prepared sample x (after reference_prep, before the group fills): one step of
// each recursion of the flight's state ``st`` (null: NaN); m{k}_ref_lp holds ewma(thr_k / s_k) until
// profile_hover divides it.
inline void physics_prep(const ProfileSpec& s, const float* raw, const VehicleRecord* vehicle, PhysState* st,
                         float* x) {
  float* ph = x + s.phys;
  if (st == nullptr) {
    for (int j = 0; j < 8; ++j) ph[j] = NAN;
    return;
  }
  ph[0] = sag_step(st->sag, x[8], s.i_b >= 0 ? raw[s.i_b] : NAN);  // v_cell, I_b
  const bool rec = vehicle != nullptr;
  const bool sag = rec && std::isfinite(vehicle->v[vehicle::kSag]);
  ph[1] = sag ? ph[0] - vehicle->v[vehicle::kSag] : s.fill[s.phys + 1];  // r_cell_ref
  float* lp = ph + 2;  // m1..4_ref_lp, vib_ref_lp, vib_ap_ref_lp: lp[j] smooths reference channel j
  for (int k = 0; k < 4; ++k) {
    const float q = rec && reference_held(*vehicle, k) ? raw[s.thr + k] / x[s.ref + k] : NAN;
    lp[k] = ewma_step(st->lp[k], q);
  }
  for (int j = 4; j < 6; ++j) lp[j] = ewma_step(st->lp[j], rec && reference_held(*vehicle, j) ? x[s.ref + j] : NAN);
  for (int j = 0; j < 6; ++j) {
    if (!rec || !reference_held(*vehicle, j)) lp[j] = s.fill[s.phys + 2 + j];
  }
}

// x (C) <- the sample's hover-independent model values; hover columns hold the raw current / commands.
// ``phys``: the flight's recursion state (the physics profile; stepped once per call).
inline void profile_prep(Profile p, const float* raw, int raw_n, float cells, float* x,
                         std::uint32_t avail = kAllGroups, const VehicleRecord* vehicle = nullptr,
                         PhysState* phys = nullptr) {
  if (p == Profile::kPaper) {
    std::memcpy(x, raw, sizeof(float) * static_cast<std::size_t>(raw_n));
    return;
  }
  const ProfileSpec& s = profile_spec(p);
  const float yaw = raw[7];
  const float c = static_cast<float>(std::cos(static_cast<double>(yaw)));
  const float sn = static_cast<float>(std::sin(static_cast<double>(yaw)));
  const float vx = raw[5], vy = raw[6];
  int j = 0;
  for (int k = 0; k < 5; ++k) x[j++] = raw[k];  // roll pitch p q r
  x[j++] = c * vx + sn * vy;
  x[j++] = -sn * vx + c * vy;
  x[j++] = raw[8];          // vz
  x[j++] = raw[9] / cells;  // v_cell
  if (s.i_b >= 0) x[j++] = raw[s.i_b];
  for (int k = 0; k < 4; ++k) x[j++] = raw[s.thr + k];
  x[j++] = raw[s.thr + 4];  // vib_px4
  if (s.vib_ap >= 0) x[j++] = raw[s.vib_ap];
  const int rpm_rel = j;  // model column of rpm1_rel (the ESC profiles)
  if (s.rpm >= 0) {  // rpm1..4, then esc_cur1..4: each over the four's collective of this sample
    for (int g = 0; g < 2; ++g) {
      const float* a = raw + s.rpm + 4 * g;
      const float collective = (((a[0] + a[1]) + a[2]) + a[3]) * 0.25f;
      for (int k = 0; k < 4; ++k) x[j++] = a[k] / collective;
    }
    const float* t = raw + s.rpm + 8;  // esc_temp1..4: each minus the four's collective of this sample
    const float common = (((t[0] + t[1]) + t[2]) + t[3]) * 0.25f;
    for (int k = 0; k < 4; ++k) x[j++] = t[k] - common;
  }
  if (s.groups == 0) return;
  if (s.ref >= 0) reference_prep(s, raw, avail, vehicle, rpm_rel, x);
  if (s.phys >= 0) physics_prep(s, raw, vehicle, phys, x);
  for (int c = 0; c < s.avail; ++c) {  // a channel needing a group the flight lacks: its fill
    if ((s.model_groups[c] & ~avail) != 0u) x[c] = s.fill[c];
  }
  for (int g = 0; g < s.groups; ++g) x[s.avail + g] = ((avail >> g) & 1u) != 0 ? 1.0f : 0.0f;
  if (s.avail_ref >= 0) x[s.avail_ref] = has_reference(vehicle) ? 1.0f : 0.0f;
}

// One prepared sample (C) -> the model's values: the hover columns divided by the frozen estimate.
// A lacking current keeps its fill (no division).
// The reference profile's m{k}_ref: m{k}_rel over the expected share prep left there (a record holding it).
inline void profile_hover(Profile p, float hover_cmd, float hover_cur, float* x, std::uint32_t avail = kAllGroups,
                          const VehicleRecord* vehicle = nullptr) {
  if (p == Profile::kPaper) return;
  const ProfileSpec& s = profile_spec(p);
  int j = 9;
  if (s.i_b >= 0) {
    if (column_present(s, avail, s.i_b)) x[j] = x[j] / hover_cur;
    ++j;
  }
  const int m_rel = j;
  for (int k = 0; k < 4; ++k, ++j) x[j] = x[j] / hover_cmd;
  if (s.ref < 0 || vehicle == nullptr) return;
  for (int k = 0; k < 4; ++k) {
    if (!reference_held(*vehicle, k)) continue;
    x[s.ref + k] = x[m_rel + k] / x[s.ref + k];
    if (s.phys >= 0) x[s.phys + 2 + k] = x[s.phys + 2 + k] / hover_cmd;  // m{k}_ref_lp
  }
}

}  // namespace fwref
