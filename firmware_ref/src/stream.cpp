// src/stream.cpp -- scope: the streaming runtime of fwref/stream.hpp: the ring of prepared samples,
// the hover estimate fed sample by sample, the window grid, the skip rules, the call of the window
// path and the alarm step. No heap; every buffer is a member sized by fwref/config.hpp.
//
// The cost of one push is bounded, whatever its timestamp (a flight controller calls push() from its
// 25 Hz loop and must get control back within the period):
//   - a refused time (repeated, backwards, non-finite, beyond kMaxGapPeriods): O(1), nothing changes;
//   - a gap of any length (1 < g <= 2^40 periods; and a new clock, after kResyncRefusals refusals):
//     skip_gap(), O(W + n) stores -- the missing samples' ring slots marked unusable (at most W), the
//     hover estimator advanced in O(1) (HoverEstimator::skip), the strides that ended inside the gap
//     counted in O(1) and the alarm stepped over them in O(min(count, n)) (AlarmPolicy::skip). It
//     reports nothing and runs no model. Filling the gap sample by sample would give the same state at
//     a cost that grows with the gap: 25 M iterations and 1.25 M stride lines (107 MB from fwref_stream)
//     for a jump of 1e6 s, minutes for 1e9 s, a controller stalled;
//   - then the sample itself: at most one stride, hence AT MOST ONE DECISION (one window inference, or
//     for a per-sample model one step and the latest step's logits). After a gap that stride is skipped
//     (its window holds a missing sample), so a push after a gap costs less than a decided push.
// tests/test_stream_gaps.py counts it: no more than one stride line per pushed sample on jumps of
// +1e6 s and +1e9 s, backwards and repeated times, and, on the Cortex-M image under QEMU (-icount), the
// worst push around a gap against the worst decision.
#include "fwref/stream.hpp"

#include <cmath>

namespace fwref {

const char* stride_status_name(StrideStatus s) {
  switch (s) {
    case StrideStatus::kNone: return "none";
    case StrideStatus::kNoHover: return "nohover";
    case StrideStatus::kSkipped: return "skipped";
    case StrideStatus::kDecided: return "decided";
  }
  return "unknown";
}

Status Stream::init(const StreamParams& p, int cells, WindowFn fn, void* ctx) {
  StreamModel m;
  m.window = fn;
  m.ctx = ctx;
  return init(p, cells, m);
}

Status Stream::init(const StreamParams& p, int cells, const StreamModel& m, std::uint64_t carried) {
  const int models = int(m.window != nullptr) + int(m.window_motor != nullptr) + int(m.step != nullptr);
  if (models != 1 || (m.step != nullptr && m.reset == nullptr)) return Status::kNullArgument;
  const int prof = static_cast<int>(p.profile);
  if (prof < 0 || prof >= kProfileCount || p.window < 2 || p.stride < 1 || p.raw_channels < 1 || p.channels < 1 ||
      p.classes < 2 || !(std::isfinite(p.sample_dt_s) && p.sample_dt_s > 0.0)) {
    return Status::kDimsInvalid;
  }
  if (p.window > kMaxWindow || p.channels > kMaxChannels || p.raw_channels > kMaxRawChannels ||
      p.classes > kMaxClasses || p.alarm.n > kMaxAlarmN) {
    return Status::kDimsTooLarge;
  }
  const ProfileSpec& spec = profile_spec(p.profile);
  const bool hover = p.profile != Profile::kPaper;
  // the physics channels' recursions step on the grid their coefficient was computed for (fwref/causal.hpp)
  if (spec.phys >= 0 && std::fabs(p.sample_dt_s - causal::kSampleDtS) > 1e-6) return Status::kDimsInvalid;
  // the masked profile may run without a cell count: set_carried() refuses V_b then
  if (hover ? (p.raw_channels != spec.raw || p.channels != spec.channels || (cells < 1 && spec.groups == 0))
            : p.raw_channels != p.channels) {
    return Status::kDimsInvalid;
  }
  AlarmParams a = p.alarm;
  a.classes = p.classes;
  if (!alarm_.configure(a)) return Status::kDimsInvalid;
  p_ = p;
  p_.alarm = a;
  cells_ = static_cast<float>(cells);
  m_ = m;
  gate_.init(p.sample_dt_s);
  resync_gap_ = std::int64_t(p.window) + std::int64_t(a.n) * p.stride;
  reset();
  carried_ = kAllCarried;
  avail_ = kAllGroups;
  has_vehicle_ = false;
  return set_carried(carried);
}

Status Stream::set_carried(std::uint64_t carried) {
  std::uint32_t avail = kAllGroups;
  if (!profile_available(p_.profile, p_.raw_channels, carried, &avail)) return Status::kDimsInvalid;
  const bool battery = p_.profile != Profile::kPaper && ((carried >> 9) & 1u) != 0;  // V_b: raw column 9
  if (battery && !(cells_ >= 1.0f)) return Status::kDimsInvalid;
  carried_ = carried;
  avail_ = avail;
  return Status::kOk;
}

Status Stream::set_vehicle(const VehicleRecord& v) {
  if (profile_spec(p_.profile).ref < 0) return Status::kDimsInvalid;
  vehicle_ = v;
  has_vehicle_ = true;
  return Status::kOk;
}

void Stream::reset() {
  hover_.reset();
  alarm_.reset();
  phys_.reset();
  last_ = Decision();
  next_ = decided_ = skipped_ = steps_ = gap_strides_ = resyncs_ = 0;
  refused_ = 0;
  if (m_.reset != nullptr) m_.reset(m_.ctx);
  t_prev_ = 0.0;
  airborne_prev_ = false;
  for (int i = 0; i < kMaxWindow; ++i) ok_[i] = false;
}

Status Stream::push(const float* sample, double t, StrideSink* sink) {
  if ((m_.window == nullptr && m_.window_motor == nullptr && m_.step == nullptr) || sample == nullptr) {
    return Status::kNullArgument;
  }
  if (!std::isfinite(t) || next_ >= kMaxSampleIndex) return Status::kBadInput;
  if (next_ > 0) {
    // llround((t - t_prev) / dt), refused below half a period: the division only off the one-period
    // path (fwref/period.hpp says why the result is the same for every t).
    const std::int64_t steps = gate_.steps(t - t_prev_);
    if (steps < 0 || steps > kMaxGapPeriods) {
      if (++refused_ < kResyncRefusals) return Status::kBadInput;
      ++resyncs_;  // the clock itself jumped: follow it, as after a gap that leaves no trace
      skip_gap(resync_gap_);
    } else if (steps > 1) {
      skip_gap(steps - 1);  // a gap: the missing samples are unusable (held, not reset)
    }
  }
  refused_ = 0;
  t_prev_ = t;
  return push_one(sample, t, sink);
}

// ``missing`` grid samples without data, in O(W + n): the state pushing that many unusable samples
// (NaN, airborne as before) would leave, without reporting the strides that end among them.
void Stream::skip_gap(std::int64_t missing) {
  const int W = p_.window;
  if (missing > kMaxSampleIndex - next_) missing = kMaxSampleIndex - next_;
  const std::int64_t marks = missing < W ? missing : W;
  int slot = static_cast<int>((next_ + missing - marks) % W);  // the last ``marks`` missing samples' slots
  for (std::int64_t j = 0; j < marks; ++j, slot = slot + 1 == W ? 0 : slot + 1) ok_[slot] = false;
  if (p_.profile != Profile::kPaper) hover_.skip(missing, airborne_prev_);
  // strides ending at e = W-1 + k * stride with next_ <= e <= last
  const std::int64_t last = next_ + missing - 1, first = next_ > W - 1 ? next_ : W - 1;
  const std::int64_t k0 = (first - (W - 1) + p_.stride - 1) / p_.stride, e0 = (W - 1) + k0 * p_.stride;
  const std::int64_t count = e0 > last ? 0 : (last - e0) / p_.stride + 1;
  next_ += missing;
  if (count == 0) return;
  // none is decided (each window holds a missing sample); nohover while the estimate has not frozen
  // (it cannot freeze on a missing sample, so for all of them alike)
  const bool nohover = p_.profile != Profile::kPaper && !hover_.frozen();
  Decision& d = last_;
  d.status = nohover ? StrideStatus::kNoHover : StrideStatus::kSkipped;
  d.index = e0 + (count - 1) * p_.stride;
  d.t = t_prev_ + double(d.index - (next_ - missing - 1)) * p_.sample_dt_s;
  d.motor = -1;
  for (int k = 0; k < p_.classes; ++k) d.logits[k] = NAN, d.proba[k] = NAN;
  for (int j = 0; j < kMotors; ++j) d.motor_logits[j] = NAN;
  d.alarm = alarm_.skip(count);
  gap_strides_ += count;  // skipped() counts the reported strides only
}

Status Stream::push_one(const float* sample, double t, StrideSink* sink) {
  const int W = p_.window, C = p_.channels, R = p_.raw_channels;
  const int slot = static_cast<int>(next_ % W);
  float* x = &ring_[slot * C];
  profile_prep(p_.profile, sample, R, cells_, x, avail_, vehicle(), &phys_);
  bool ok = true;
  const bool hover = p_.profile != Profile::kPaper;
  for (int c = 0; c < (hover ? R - 1 : R); ++c) {  // a column the flight lacks is not read
    const bool carried = c >= 64 || ((carried_ >> c) & 1u) != 0;
    ok = ok && (!carried || std::isfinite(sample[c]));
  }
  if (hover) {
    const HoverInputs h = hover_inputs(p_.profile, sample, avail_);
    hover_.push(h.vz, h.roll, h.pitch, h.thr, h.current, h.airborne);
    ok = ok && h.airborne;
    airborne_prev_ = h.airborne;
  }
  const std::int64_t end = next_;  // this sample's index
  const bool ends_stride = end >= W - 1 && (end - (W - 1)) % p_.stride == 0;
  if (m_.step != nullptr && ok) ok = step_sample(x, ends_stride);
  ok_[slot] = ok;
  ++next_;
  if (ends_stride) stride(t, sink);
  return Status::kOk;
}

void Stream::stride(double t, StrideSink* sink) {
  const int W = p_.window, C = p_.channels, K = p_.classes;
  Decision& d = last_;
  d.index = next_ - 1;
  d.t = t;
  d.motor = -1;
  for (int j = 0; j < kMotors; ++j) d.motor_logits[j] = NAN;
  const bool hover = p_.profile != Profile::kPaper;
  if (hover && !(hover_.frozen() && hover_.freeze_index() <= d.index)) {
    d.status = StrideStatus::kNoHover;
  } else {
    bool ok = true;
    const int first = static_cast<int>((next_ - W) % W);  // slot of the window's oldest sample
    for (int j = 0; j < W && ok; ++j) {
      const int slot = (first + j) % W;
      ok = ok_[slot];
      if (m_.step != nullptr) continue;  // a per-sample model checked each row as it stepped it
      float* row = &win_[j * C];
      for (int c = 0; c < C; ++c) row[c] = ring_[slot * C + c];
      if (hover) profile_hover(p_.profile, hover_.cmd(), hover_.cur(), row, avail_, vehicle());
      for (int c = 0; c < C && ok; ++c) ok = std::isfinite(row[c]);
    }
    d.status = ok && run_window(d) == Status::kOk ? StrideStatus::kDecided : StrideStatus::kSkipped;
  }
  if (d.status == StrideStatus::kDecided) {
    double mx = d.logits[0], sum = 0.0;
    for (int k = 1; k < K; ++k) mx = d.logits[k] > mx ? double(d.logits[k]) : mx;
    for (int k = 0; k < K; ++k) sum += (d.proba[k] = std::exp(double(d.logits[k]) - mx));
    for (int k = 0; k < K; ++k) d.proba[k] /= sum;
    if (m_.window_motor != nullptr) {  // softmax of the motor logits, in double (core/alarm.py's motor_proba)
      double mm = d.motor_logits[0], ms = 0.0;
      d.motor = 0;
      for (int j = 1; j < kMotors; ++j) {
        if (d.motor_logits[j] > d.motor_logits[d.motor]) d.motor = j;  // first maximum, numpy's argmax
        mm = d.motor_logits[j] > mm ? double(d.motor_logits[j]) : mm;
      }
      for (int j = 0; j < kMotors; ++j) ms += (motor_proba_[j] = std::exp(double(d.motor_logits[j]) - mm));
      for (int j = 0; j < kMotors; ++j) motor_proba_[j] /= ms;
    }
    ++decided_;
  } else {
    for (int k = 0; k < K; ++k) d.logits[k] = NAN, d.proba[k] = NAN;
    skipped_ += d.status == StrideStatus::kSkipped ? 1 : 0;
  }
  if (m_.window_motor != nullptr && d.status != StrideStatus::kDecided) {
    for (int j = 0; j < kMotors; ++j) motor_proba_[j] = 0.0;  // not read: an undecided stride never votes
  }
  d.alarm = alarm_.step(d.proba, m_.window_motor != nullptr ? motor_proba_ : nullptr,
                        d.status == StrideStatus::kDecided);
  if (sink != nullptr) sink->on_stride(d);
}

// The per-sample model on sample x (the prepared ring row): the model row (hover columns divided by
// the frozen estimate), one step; false (the sample is unusable, the state held) when the estimate
// has not frozen yet, a model value is not finite or the step fails. The logits are asked for only
// when the sample ends a stride (the only ones a decision reads; StepFn's null logits: no head).
bool Stream::step_sample(const float* x, bool ends_stride) {
  const int C = p_.channels;
  if (p_.profile != Profile::kPaper) {
    if (!hover_.frozen()) return false;
    for (int c = 0; c < C; ++c) step_row_[c] = x[c];
    profile_hover(p_.profile, hover_.cmd(), hover_.cur(), step_row_, avail_, vehicle());
    x = step_row_;
  }
  for (int c = 0; c < C; ++c) {
    if (!std::isfinite(x[c])) return false;
  }
  if (m_.step(m_.ctx, x, ends_stride ? step_logits_ : nullptr) != Status::kOk) return false;
  ++steps_;
  return true;
}

// The decision of a stride whose window is usable: the window path, or the latest step's logits.
Status Stream::run_window(Decision& d) {
  if (m_.step != nullptr) {
    for (int k = 0; k < p_.classes; ++k) d.logits[k] = step_logits_[k];
    return Status::kOk;
  }
  if (m_.window_motor != nullptr) return m_.window_motor(m_.ctx, win_, d.logits, d.motor_logits);
  return m_.window(m_.ctx, win_, d.logits);
}

}  // namespace fwref
