// fwref/stream.hpp -- scope: the on-board streaming runtime (docs/firmware.md
// "Streaming"): one raw telemetry sample at a time in, a decision at every stride out, with the
// arithmetic of the window path (the Python one: detect/, and the C++ one: infer() on a window).
// C++17, no heap, every buffer sized at compile time by fwref/config.hpp (kMaxWindow,
// kMaxChannels, kMaxRawChannels, kMaxClasses, kMaxAlarmN).
//
//   fwref::Stream s;                        // 2 * W * C floats + the alarm's ring: make it static
//   s.init(params, cells, run_window, ctx);  // params from weights.bin's on-board record
//   s.push(sample, t);                       // sample: the record's raw channels, in its order
//   if (s.last().status == fwref::StrideStatus::kDecided) { s.last().proba; s.last().alarm; }
//   s.reset();                               // between flights
//
// Per sample: the profile's hover-independent values go into a ring of the window length
// (fwref/profile.hpp) and the hover estimator (fwref/hover.hpp) takes the sample. At every stride
// once W samples have arrived (window ends at samples W-1, W-1+stride, ...: the window grid of
// detect/ and train/) the stride has one outcome:
//   kNoHover  the hover estimate has not frozen by the window's last sample: no decision;
//   kSkipped  a sample of the window is unusable: NaN/Inf in a raw channel or a model value, or not
//             airborne (the profiles with a hover estimate), as detect/inputs.py skips it;
//   kDecided  the window (hover columns divided by the frozen estimate) runs through the window
//             path (``WindowFn``: infer() of cnode.cpp / gru.cpp), softmax in double.
// Every stride then steps the alarm policy (fwref/alarm.hpp; only kDecided strides are valid).
// No decision before W samples; reset() forgets everything (ring, hover estimate, alarm, model state).
//
// A windowed model with its motor head (``WindowMotorFn``: infer_motor()) also gives, at every
// kDecided stride, the motor logits: Decision::motor is their argmax (0..3), and the alarm policy
// takes their softmax (core/alarm.py's motor rule 4), so Decision::alarm.motor is the alarm's motor,
// reported (rule 5) only while the alarm's class is rotor-side (StreamParams::alarm.rotor_mask, from
// the record's alarm.rotor_side): a BatteryFault alarm reports -1, as `quadfdi detect` does.
//
// A per-sample model (``StepFn``: the streaming GRU, fwref/gru_step.hpp) steps on every usable
// sample as it is pushed, with the sample's model row (the profile's values, hover columns divided
// by the frozen estimate); the decision at a stride is the logits of the latest step (the state
// after the window's last sample), never a recomputation. Its state:
//   - h = 0 at init() and reset() (``ResetFn``), i.e. at take-off, as train/stream_gru_run.py
//     evaluates it (one stream per flight, started at h = 0 on its first sample);
//   - an unusable sample (NaN/Inf raw or model value, not airborne, or a sample missing in a timestamp gap) is
//     not stepped: h is held across it (and the strides whose window holds it are kSkipped, as for
//     the windowed models, so that all models vote on the same strides);
//   - profiles with a hover estimate: no sample is stepped before the estimate has frozen (the model
//     row needs it), so the state starts at h = 0 on the freezing sample; strides before: kNoHover.
// detect/streamref.py ``step_rows`` is the Python statement of these rules.
//
// Channels a flight lacks (the masked profile only, fwref/profile.hpp): init() and set_carried() take
// the columns the flight's stream carries (formats/stream.py's carried flags; bit r: raw column r);
// the availability mask follows from them once per flight, a lacking group's model channels take
// their fills and its columns are not checked for NaN. A profile without a mask needs every column.
//
// The vehicle record (a reference profile only, fwref/vehicle_record.hpp): set_vehicle() after init() or
// reset(), before the flight's first sample, copies the record's floats into the stream (100 bytes, no pointer
// kept); reset() keeps it (the record belongs to the vehicle, not the flight), clear_vehicle() drops it.
// Without one the reference channels take their fills and avail_reference is 0.
//
// The physics profile (fwref/profile.hpp, fwref/causal.hpp): its recursions step on every pushed sample from
// the flight's first (reset() starts them again), hold their state across an unusable sample and across a
// gap's missing samples (as pushing NaN would); init() refuses (kDimsInvalid) a sample period other than
// the one their coefficient was computed for (causal::kSampleDtS).
//
// Timestamps: each sample carries its time t (s); the stream runs on the grid of the record's sample
// period dt, and a time step counts g = llround((t - t_prev) / dt) periods (fwref/period.hpp's
// PeriodGate: the same decision for every t, no division on the one-period path). Every push costs at
// most ONE decision's work, whatever the times (src/stream.cpp says how):
//   g = 1        the next sample;
//   1 < g <= 2^40  a gap of g - 1 missing samples, HELD, not reset: the state is what pushing g - 1
//                unusable samples (NaN, airborne as before) would leave -- the windows holding them are
//                skipped, the stride phase, the frozen hover estimate and the alarm carry on, the
//                per-sample model's state is held -- but it is set in O(W + n), not sample by sample:
//                the strides that END INSIDE the gap are not reported (no sink call: on board nothing
//                runs between two samples); they are counted (gap_strides()) and step the alarm as
//                invalid windows; last() is the latest of them. So a push reports at most one stride,
//                the one its own sample ends, and after a gap that stride is never decided (its window
//                holds a missing sample): a push after a gap runs no window inference (a per-sample
//                model still steps once, on the pushed sample);
//   g < 1 (a time that does not advance by half a period: repeated, backwards) or g > 2^40 (1,400
//                years at 25 Hz: a corrupt time), and a non-finite t: REFUSED (kBadInput), the sample
//                dropped, the state untouched;
//   kResyncRefusals consecutive refused finite times: the clock itself has jumped (a reset, or a
//                glitch that was accepted as a gap and left the true times behind it): that sample is
//                taken as the first after a gap of W + n * stride missing samples (every window across
//                it skipped, the alarm's last n strides empty; hover estimate and an active alarm carry
//                on), and the stream follows the new clock (resyncs()).
// The sample index (samples(), Decision::index) counts the grid, gap samples included; past 2^62
// (1.8e11 years at 25 Hz) every push is refused until reset().
#pragma once

#include <cstdint>

#include "fwref/alarm.hpp"
#include "fwref/config.hpp"
#include "fwref/gru_step.hpp"
#include "fwref/hover.hpp"
#include "fwref/motor.hpp"
#include "fwref/period.hpp"
#include "fwref/profile.hpp"
#include "fwref/status.hpp"
#include "fwref/vehicle_record.hpp"

// The Cortex-M stream image sets these two through a generated header (quadfdi.runtimes.mcu_stream_src).
#ifdef FWREF_STREAM_LIMITS_HEADER
#include FWREF_STREAM_LIMITS_HEADER
#endif
#ifndef FWREF_MAX_RAW_CHANNELS
#define FWREF_MAX_RAW_CHANNELS FWREF_MAX_CHANNELS
#endif
#ifndef FWREF_MAX_ALARM_N
#define FWREF_MAX_ALARM_N 64
#endif

namespace fwref {

constexpr int kMaxRawChannels = FWREF_MAX_RAW_CHANNELS;  // channels of one stream sample
constexpr int kMaxAlarmN = FWREF_MAX_ALARM_N;            // the alarm policy's n
constexpr int kHoverSteady = 50;                         // core.hover.STEADY_SAMPLES, compiled in
constexpr std::int64_t kMaxGapPeriods = std::int64_t(1) << 40;  // a longer forward step is a corrupt time
constexpr int kResyncRefusals = 8;                        // refused times in a row that mean a new clock
constexpr std::int64_t kMaxSampleIndex = std::int64_t(1) << 62;

// What the stream needs besides the weights: weights.bin's on-board record (fwref/onboard.hpp).
struct StreamParams {
  Profile profile;
  int window;          // W
  int stride;          // samples between decisions
  int raw_channels;    // R, channels of one sample
  int channels;        // C, the model's
  int classes;         // K
  double sample_dt_s;  // the grid period
  AlarmParams alarm;   // rotor_mask: the record's alarm.rotor_side (every class without it)
};

enum class StrideStatus : int { kNone = 0, kNoHover = 1, kSkipped = 2, kDecided = 3 };
const char* stride_status_name(StrideStatus s);

// The outcome of one stride (the latest: Stream::last()).
struct Decision {
  StrideStatus status = StrideStatus::kNone;
  std::int64_t index = -1;  // sample index of the window's last sample (0 = the first pushed)
  double t = 0.0;           // its timestamp, s
  float logits[kMaxClasses] = {};
  double proba[kMaxClasses] = {};  // softmax of the logits (kDecided only)
  AlarmStep alarm{false, false, false, false, -1, -1};
  int motor = -1;  // this stride's suspected motor (0..3): argmax of the motor head; -1 without a head or decision
  float motor_logits[kMotors] = {};  // the motor head's logits (kDecided with a head; NaN otherwise)
};

// The window path: Status infer(model, window (W, C), logits (K)) behind a plain function pointer.
using WindowFn = Status (*)(void* ctx, const float* window, float* logits);
// The window path with its motor head: infer_motor(model, head, window, logits (K), motor (kMotors)).
using WindowMotorFn = Status (*)(void* ctx, const float* window, float* logits, float* motor);
// A per-sample model: one step on a usable sample's model row (C), the logits (K) of the new state;
// logits null (the sample ends no stride: no decision reads them) skips the head.
using StepFn = Status (*)(void* ctx, const float* row, float* logits);
using ResetFn = void (*)(void* ctx);  // the per-sample model's state back to take-off (h = 0)

// What the stream runs: exactly one of window, window_motor, step (step needs reset).
struct StreamModel {
  WindowFn window = nullptr;
  WindowMotorFn window_motor = nullptr;
  StepFn step = nullptr;
  ResetFn reset = nullptr;
  void* ctx = nullptr;
};

template <class Model, class Workspace>
struct WindowRunner {
  const Model* model;
  Workspace* ws;
  static Status run(void* ctx, const float* window, float* logits);
};

// A net and its motor head (fwref/motor.hpp) as a WindowMotorFn.
template <class Model, class Head, class Workspace>
struct WindowMotorRunner {
  const Model* model;
  const Head* head;
  Workspace* ws;
  static Status run(void* ctx, const float* window, float* logits, float* motor) {
    auto* self = static_cast<WindowMotorRunner*>(ctx);
    return infer_motor(*self->model, *self->head, window, logits, motor, *self->ws);
  }
};

// A per-sample model (fwref/gru_step.hpp: GruF32 / GruI8 with window 1) as a StepFn / ResetFn.
template <class Model, class State>
struct StepRunner {
  const Model* model;
  State* state;
  static Status step(void* ctx, const float* row, float* logits) {
    auto* self = static_cast<StepRunner*>(ctx);
    return fwref::step(*self->model, row, *self->state, logits);
  }
  static void reset(void* ctx) {
    auto* self = static_cast<StepRunner*>(ctx);
    fwref::reset(*self->model, *self->state);
  }
};

// Called for every reported stride: at most one per push (the stride the pushed sample ends); optional.
class StrideSink {
 public:
  virtual void on_stride(const Decision& d) = 0;

 protected:
  ~StrideSink() = default;
};

class Stream {
 public:
  // kDimsTooLarge / kDimsInvalid when the parameters exceed this build's capacity or disagree with
  // the profile; ``cells`` the pack's cell count (profiles with a hover estimate; ignored otherwise;
  // the masked profile needs it only while the stream carries V_b); ``carried`` as set_carried.
  Status init(const StreamParams& p, int cells, WindowFn fn, void* ctx);
  Status init(const StreamParams& p, int cells, const StreamModel& m,  // kNullArgument: not exactly one model
              std::uint64_t carried = kAllCarried);
  // The raw columns this flight's stream carries (bit r: column r); call after init() or reset(), before
  // the flight's first sample. kDimsInvalid (the previous columns kept): a profile without a mask lacking
  // a column, the masked profile lacking its minimum, or V_b carried without a cell count.
  Status set_carried(std::uint64_t carried);
  std::uint32_t available() const { return avail_; }  // the availability mask (bit g: group g of kGroupNames)
  // The vehicle record the reference channels read (copied); kDimsInvalid (nothing changed) for a profile
  // without them. avail_reference is 1 when its first share is finite (fwref/profile.hpp).
  Status set_vehicle(const VehicleRecord& v);
  void clear_vehicle() { has_vehicle_ = false; }
  const VehicleRecord* vehicle() const { return has_vehicle_ ? &vehicle_ : nullptr; }  // null: none loaded
  // One sample (R raw channels, the record's order) at time t; kBadInput: a refused time (not finite, not
  // advancing by half a period, more than kMaxGapPeriods ahead), the sample dropped. At most one decision.
  Status push(const float* sample, double t, StrideSink* sink = nullptr);
  void reset();  // a new flight: ring, hover estimate, alarm and time forgotten

  const Decision& last() const { return last_; }  // the latest stride (status kNone before any)
  std::int64_t samples() const { return next_; }  // samples pushed, filled gap samples included
  bool hover_frozen() const { return hover_.frozen(); }
  float hover_cmd() const { return hover_.cmd(); }
  float hover_cur() const { return hover_.cur(); }
  std::int64_t decided() const { return decided_; }
  std::int64_t skipped() const { return skipped_; }  // reported kSkipped strides (not those inside a gap)
  std::int64_t steps() const { return steps_; }  // per-sample model steps since reset (0 for a windowed model)
  std::int64_t gap_strides() const { return gap_strides_; }  // strides that ended inside a gap (not reported)
  std::int64_t resyncs() const { return resyncs_; }          // times the stream took a new clock

 private:
  Status push_one(const float* sample, double t, StrideSink* sink);
  void skip_gap(std::int64_t missing);
  void stride(double t, StrideSink* sink);
  bool step_sample(const float* x, bool ends_stride);
  Status run_window(Decision& d);

  StreamParams p_{};
  float cells_ = 0.0f;
  std::uint64_t carried_ = kAllCarried;  // the raw columns the flight's stream carries
  std::uint32_t avail_ = kAllGroups;     // the availability mask they give (fwref/profile.hpp)
  VehicleRecord vehicle_{};              // the reference profile's vehicle record (has_vehicle_)
  bool has_vehicle_ = false;
  StreamModel m_{};
  float ring_[kMaxWindow * kMaxChannels] = {};  // prepared samples, slot = index % W
  bool ok_[kMaxWindow] = {};                    // the sample is usable
  float win_[kMaxWindow * kMaxChannels] = {};   // the window handed to the model, oldest first
  float step_row_[kMaxChannels] = {};
  float step_logits_[kMaxClasses] = {};  // the latest step's (per-sample model)
  double motor_proba_[kMaxClasses > kMotors ? kMaxClasses : kMotors] = {};
  HoverEstimator<kHoverSteady> hover_;
  PhysState phys_;  // the physics profile's recursions over the flight (fwref/causal.hpp)
  AlarmPolicy<kMaxAlarmN, kMaxClasses> alarm_;
  Decision last_;
  std::int64_t next_ = 0, decided_ = 0, skipped_ = 0, steps_ = 0, gap_strides_ = 0, resyncs_ = 0;
  std::int64_t resync_gap_ = 0;  // W + n * stride: the missing samples a new clock stands for
  int refused_ = 0;              // refused finite times in a row
  double t_prev_ = 0.0;
  PeriodGate gate_;  // the timestamp step's period count, bounds formed once by init()
  bool airborne_prev_ = false;
};

template <class Model, class Workspace>
Status WindowRunner<Model, Workspace>::run(void* ctx, const float* window, float* logits) {
  auto* self = static_cast<WindowRunner*>(ctx);
  return infer(*self->model, window, logits, *self->ws);
}

}  // namespace fwref
