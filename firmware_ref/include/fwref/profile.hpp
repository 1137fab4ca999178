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
#pragma once

#include <cmath>
#include <cstring>

#include "fwref/channels_gen.hpp"  // Profile, ProfileSpec and the profiles' channel lists, from core/channels.py

namespace fwref {

inline const ProfileSpec& profile_spec(Profile p) { return profile_tables::kSpecs[static_cast<int>(p)]; }

// The inputs of the hover estimate (fwref/hover.hpp) in one raw sample of a hover profile.
struct HoverInputs {
  float vz, roll, pitch, thr[4], current;
  bool airborne;
};

inline HoverInputs hover_inputs(Profile p, const float* raw) {
  const ProfileSpec& s = profile_spec(p);
  HoverInputs h{raw[8], raw[0], raw[1], {raw[s.thr], raw[s.thr + 1], raw[s.thr + 2], raw[s.thr + 3]},
                s.i_b >= 0 ? raw[s.i_b] : NAN, raw[s.raw - 1] >= 0.5f};  // NaN airborne: not airborne
  return h;
}

// x (C) <- the sample's hover-independent model values; hover columns hold the raw current / commands.
inline void profile_prep(Profile p, const float* raw, int raw_n, float cells, float* x) {
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
}

// One prepared sample (C) -> the model's values: the hover columns divided by the frozen estimate.
inline void profile_hover(Profile p, float hover_cmd, float hover_cur, float* x) {
  if (p == Profile::kPaper) return;
  const ProfileSpec& s = profile_spec(p);
  int j = 9;
  if (s.i_b >= 0) x[j] = x[j] / hover_cur, ++j;
  for (int k = 0; k < 4; ++k, ++j) x[j] = x[j] / hover_cmd;
}

}  // namespace fwref
