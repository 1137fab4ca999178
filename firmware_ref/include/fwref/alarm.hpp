// fwref/alarm.hpp -- scope: the alarm policy of core/alarm.py, one window at a time, fixed size, no
// heap (docs/firmware.md "Streaming"). Same decisions as Python on the same inputs:
//
//   vote_i  = valid_i && (1 - proba_i[healthy]) >= threshold      (double, as Python's float64)
//   raise   at i: not active && vote_i && (votes among windows i-n+1..i) >= k
//   clear   at i: active && valid_i && !latch && (consecutive non-voting valid windows) >= clear_m
//   class   argmax over the fault columns of S, the summed proba of the episode's voting windows
//           (at the raise: the voting windows among the last n); ties -> the lowest index;
//   motor   likewise over the summed motor_proba (rule 4), REPORTED only when the alarm's class is
//           rotor-side (rule 5, core.alarm.reported_motor: bit cls of rotor_mask set), else -1;
//           -1 also without motor_proba. The default mask (every bit set) is rule 4 alone: what a
//           weights.bin written before the record's alarm.rotor_side tensor gives.
//
// An invalid window (no decision: before the hover estimate froze, a skipped window) takes its
// slot among the last n without voting, and neither raises, clears nor counts towards a clear.
// S sums the last n windows oldest first, where Python subtracts cumulative sums: the class can
// differ only on a near-exact tie of two summed probabilities (core/alarm.py says so too).
//
//   fwref::AlarmPolicy<64, 16> a;  a.configure({0.5, 2, 3, 3, false, 0, 5});
//   const fwref::AlarmStep s = a.step(proba, nullptr, true);
#pragma once

#include <cstdint>

#include "fwref/contracts_gen.hpp"  // AlarmParams: the policy's keys from core/contracts.py POLICY_FIELDS

namespace fwref {

struct AlarmStep {
  bool vote, active, raised, cleared;
  int cls;    // the alarm's class, -1 while inactive
  int motor;  // its reported motor 0..3 (rule 5), -1 while inactive, without motor_proba or for a class
             // that is not rotor-side
};

template <int MaxN, int MaxClasses>
class AlarmPolicy {
  static_assert(MaxN >= 1 && MaxClasses >= 2, "at least one window and two classes");
  static_assert(MaxClasses <= 32, "AlarmParams::rotor_mask holds one bit per class");

 public:
  // False (and nothing changed) if the parameters are outside core.alarm.check_policy's ranges or
  // this instance's capacity.
  bool configure(const AlarmParams& p) {
    if (!(p.threshold > 0.0 && p.threshold <= 1.0) || p.k < 1 || p.k > p.n || p.n > MaxN || p.clear_m < 1 ||
        p.classes < 2 || p.classes > MaxClasses || p.healthy < 0 || p.healthy >= p.classes) {
      return false;
    }
    p_ = p;
    reset();
    return true;
  }

  // Back to no alarm and no history (a new flight).
  void reset() {
    active_ = false;
    run_ = 0;
    filled_ = 0;
    head_ = 0;
  }

  // One window in time order: proba (K) and motor_proba (4, may be null); ``valid`` false for a
  // window without a decision (proba is then not read).
  AlarmStep step(const double* proba, const double* motor_proba, bool valid) {
    const int K = p_.classes;
    const bool v = valid && (1.0 - proba[p_.healthy]) >= p_.threshold;
    // this window's slot in the ring of the last n
    double* vp = vp_[head_];
    double* mp = mp_[head_];
    votes_[head_] = v;
    for (int c = 0; c < K; ++c) vp[c] = v ? proba[c] : 0.0;
    for (int m = 0; m < 4; ++m) mp[m] = v && motor_proba ? motor_proba[m] : 0.0;
    head_ = (head_ + 1) % p_.n;
    if (filled_ < p_.n) ++filled_;

    if (active_ && valid) run_ = v ? 0 : run_ + 1;
    const bool clear = active_ && valid && !p_.latch && run_ >= p_.clear_m;
    if (clear) active_ = false;
    int count = 0;
    for (int j = 0; j < filled_; ++j) count += votes_[j] ? 1 : 0;
    const bool rise = !active_ && v && count >= p_.k;
    if (rise) {  // S = the voting windows among the last n, oldest first
      for (int c = 0; c < K; ++c) s_[c] = 0.0;
      for (int m = 0; m < 4; ++m) sm_[m] = 0.0;
      for (int j = 0; j < filled_; ++j) {
        const int slot = (head_ - filled_ + j + 2 * p_.n) % p_.n;
        for (int c = 0; c < K; ++c) s_[c] += vp_[slot][c];
        for (int m = 0; m < 4; ++m) sm_[m] += mp_[slot][m];
      }
      has_motor_ = motor_proba != nullptr;
    } else if (active_ && v) {
      for (int c = 0; c < K; ++c) s_[c] += vp[c];
      for (int m = 0; m < 4; ++m) sm_[m] += mp[m];
    }
    active_ = active_ || rise;
    if (rise) run_ = 0;
    return report(AlarmStep{v, active_, rise, clear, -1, -1});
  }

  // ``m`` windows in a row without a decision (the strides a gap in a stream passed over), in
  // O(min(m, n)): the state, and the step of the last of them, that m step(..., false) give. An invalid
  // window only takes its slot (no vote), so past n of them every slot is empty and the rest change
  // nothing but the ring's head; an active alarm stays active (only valid windows clear it).
  AlarmStep skip(std::int64_t m) {
    if (m <= 0) return report(AlarmStep{false, active_, false, false, -1, -1});
    const int n = p_.n, empty = m < n ? int(m) : n;
    for (int j = 0; j < empty; ++j) {
      const int slot = (head_ + j) % n;
      votes_[slot] = false;
      for (int c = 0; c < p_.classes; ++c) vp_[slot][c] = 0.0;
      for (int k = 0; k < 4; ++k) mp_[slot][k] = 0.0;
    }
    head_ = int((head_ + m % n) % n);
    filled_ = m >= n - filled_ ? n : filled_ + int(m);
    return report(AlarmStep{false, active_, false, false, -1, -1});
  }

  const AlarmParams& params() const { return p_; }
  bool active() const { return active_; }

 private:
  // The episode's class and reported motor (rules 4-5) into ``out`` while active.
  AlarmStep report(AlarmStep out) const {
    if (active_) {
      for (int c = 0; c < p_.classes; ++c) {
        if (c != p_.healthy && (out.cls < 0 || s_[c] > s_[out.cls])) out.cls = c;
      }
      if (has_motor_ && out.cls >= 0 && ((p_.rotor_mask >> out.cls) & 1u) != 0) {  // rule 5
        out.motor = 0;
        for (int m = 1; m < 4; ++m) out.motor = sm_[m] > sm_[out.motor] ? m : out.motor;
      }
    }
    return out;
  }

  AlarmParams p_{0.5, 2, 3, 3, false, 0, 2};
  bool votes_[MaxN] = {};
  double vp_[MaxN][MaxClasses] = {};
  double mp_[MaxN][4] = {};
  double s_[MaxClasses] = {};
  double sm_[4] = {};
  int head_ = 0, filled_ = 0, run_ = 0;
  bool active_ = false, has_motor_ = false;
};

}  // namespace fwref
