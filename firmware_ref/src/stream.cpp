// src/stream.cpp -- scope: the streaming runtime of fwref/stream.hpp: the ring of prepared samples,
// the hover estimate fed sample by sample, the window grid, the skip rules, the call of the window
// path and the alarm step. No heap; every buffer is a member sized by fwref/config.hpp.
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
  if (fn == nullptr) return Status::kNullArgument;
  const int prof = static_cast<int>(p.profile);
  if (prof < 0 || prof >= kProfileCount || p.window < 2 || p.stride < 1 || p.raw_channels < 1 || p.channels < 1 ||
      p.classes < 2 || !(p.sample_dt_s > 0.0)) {
    return Status::kDimsInvalid;
  }
  if (p.window > kMaxWindow || p.channels > kMaxChannels || p.raw_channels > kMaxRawChannels ||
      p.classes > kMaxClasses || p.alarm.n > kMaxAlarmN) {
    return Status::kDimsTooLarge;
  }
  const ProfileSpec& spec = profile_spec(p.profile);
  const bool hover = p.profile != Profile::kPaper;
  if (hover ? (p.raw_channels != spec.raw || p.channels != spec.channels || cells < 1)
            : p.raw_channels != p.channels) {
    return Status::kDimsInvalid;
  }
  AlarmParams a = p.alarm;
  a.classes = p.classes;
  if (!alarm_.configure(a)) return Status::kDimsInvalid;
  p_ = p;
  p_.alarm = a;
  cells_ = static_cast<float>(cells);
  fn_ = fn;
  ctx_ = ctx;
  for (int c = 0; c < kMaxRawChannels; ++c) nan_sample_[c] = NAN;
  reset();
  return Status::kOk;
}

void Stream::reset() {
  hover_.reset();
  alarm_.reset();
  last_ = Decision();
  next_ = decided_ = skipped_ = 0;
  t_prev_ = 0.0;
  airborne_prev_ = false;
  for (int i = 0; i < kMaxWindow; ++i) ok_[i] = false;
}

Status Stream::push(const float* sample, double t, StrideSink* sink) {
  if (fn_ == nullptr || sample == nullptr) return Status::kNullArgument;
  if (!std::isfinite(t)) return Status::kBadInput;
  if (next_ > 0) {
    const double periods = (t - t_prev_) / p_.sample_dt_s;
    if (!(periods >= 0.5)) return Status::kBadInput;  // also NaN
    const std::int64_t steps = static_cast<std::int64_t>(std::llround(periods));
    for (std::int64_t g = 1; g < steps; ++g) {  // a gap: the missing samples are unusable (held, not reset)
      nan_sample_[p_.raw_channels - 1] = airborne_prev_ ? 1.0f : 0.0f;
      push_one(nan_sample_, t_prev_ + double(g) * p_.sample_dt_s, sink);
    }
  }
  t_prev_ = t;
  return push_one(sample, t, sink);
}

Status Stream::push_one(const float* sample, double t, StrideSink* sink) {
  const int W = p_.window, C = p_.channels, R = p_.raw_channels;
  const int slot = static_cast<int>(next_ % W);
  float* x = &ring_[slot * C];
  profile_prep(p_.profile, sample, R, cells_, x);
  bool ok = true;
  const bool hover = p_.profile != Profile::kPaper;
  for (int c = 0; c < (hover ? R - 1 : R); ++c) ok = ok && std::isfinite(sample[c]);
  if (hover) {
    const HoverInputs h = hover_inputs(p_.profile, sample);
    hover_.push(h.vz, h.roll, h.pitch, h.thr, h.current, h.airborne);
    ok = ok && h.airborne;
    airborne_prev_ = h.airborne;
  }
  ok_[slot] = ok;
  ++next_;
  const std::int64_t end = next_ - 1;  // this sample's index
  if (end >= W - 1 && (end - (W - 1)) % p_.stride == 0) stride(t, sink);
  return Status::kOk;
}

void Stream::stride(double t, StrideSink* sink) {
  const int W = p_.window, C = p_.channels, K = p_.classes;
  Decision& d = last_;
  d.index = next_ - 1;
  d.t = t;
  d.motor = -1;
  const bool hover = p_.profile != Profile::kPaper;
  if (hover && !(hover_.frozen() && hover_.freeze_index() <= d.index)) {
    d.status = StrideStatus::kNoHover;
  } else {
    bool ok = true;
    const int first = static_cast<int>((next_ - W) % W);  // slot of the window's oldest sample
    for (int j = 0; j < W && ok; ++j) {
      const int slot = (first + j) % W;
      ok = ok_[slot];
      float* row = &win_[j * C];
      for (int c = 0; c < C; ++c) row[c] = ring_[slot * C + c];
      if (hover) profile_hover(p_.profile, hover_.cmd(), hover_.cur(), row);
      for (int c = 0; c < C && ok; ++c) ok = std::isfinite(row[c]);
    }
    d.status = ok && fn_(ctx_, win_, d.logits) == Status::kOk ? StrideStatus::kDecided : StrideStatus::kSkipped;
  }
  if (d.status == StrideStatus::kDecided) {
    double mx = d.logits[0], sum = 0.0;
    for (int k = 1; k < K; ++k) mx = d.logits[k] > mx ? double(d.logits[k]) : mx;
    for (int k = 0; k < K; ++k) sum += (d.proba[k] = std::exp(double(d.logits[k]) - mx));
    for (int k = 0; k < K; ++k) d.proba[k] /= sum;
    ++decided_;
  } else {
    for (int k = 0; k < K; ++k) d.logits[k] = NAN, d.proba[k] = NAN;
    skipped_ += d.status == StrideStatus::kSkipped ? 1 : 0;
  }
  d.alarm = alarm_.step(d.proba, nullptr, d.status == StrideStatus::kDecided);
  if (sink != nullptr) sink->on_stride(d);
}

}  // namespace fwref
