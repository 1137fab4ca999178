// fwref/hover.hpp -- scope: the collective hover estimate of core/hover.py, sample by sample, in
// float32, fixed size, no heap (docs/profiles.md). Feed one grid sample at a time (25 Hz):
//
//   fwref::HoverEstimator<50> h;                      // N steady samples (core.hover.STEADY_SAMPLES)
//   h.push(vz, roll, pitch, thr, current, airborne);  // thr: the four motor commands
//   if (h.frozen()) { h.cmd(); h.cur(); h.freeze_index(); }
//
// Same arithmetic as Python, in the same order, so the estimates are bit-identical:
//   collective c = (((thr1 + thr2) + thr3) + thr4) * 0.25f;
//   steady = airborne for more than 50 samples since the last take-off (a flight starting airborne
//            counts as settled) && vz, roll, pitch, thr finite (not the current) && |vz| <= 0.5f && |roll| <= 0.25f && |pitch| <= 0.25f
//            && c >= 0.05f;
//   at the first sample ending N consecutive steady samples: cmd = (sum of c over them, oldest
//   first, float accumulator from 0) / float(N); cur likewise over the current; then frozen.
// Requires IEEE float32 without contraction of the sums (x86-64 SSE, Cortex-M4F/M7 FPU: no FMA
// is formed from an add alone).
#pragma once

#include <cmath>
#include <cstdint>

namespace fwref {

struct HoverLimits {
    static constexpr float kVzMax = 0.5f;
    static constexpr float kTiltMax = 0.25f;
    static constexpr float kCmdMin = 0.05f;
    static constexpr int kSettle = 50;  // samples airborne after a take-off before one can be steady
};

template <int N>
class HoverEstimator {
    static_assert(N >= 1, "at least one steady sample");

public:
    // Feed sample number index() (0, 1, ...); returns true while the estimate is frozen.
    bool push(float vz, float roll, float pitch, const float thr[4], float current, bool airborne) {
        const int64_t i = index_++;
        if (frozen_) return true;
        const float c = (((thr[0] + thr[1]) + thr[2]) + thr[3]) * 0.25f;
        const bool finite = std::isfinite(vz) && std::isfinite(roll) && std::isfinite(pitch) &&
                            std::isfinite(thr[0]) && std::isfinite(thr[1]) && std::isfinite(thr[2]) &&
                            std::isfinite(thr[3]);  // the current may be NaN (no sensor): cur is then NaN
        // settled: airborne for more than kSettle samples since the last take-off; the counter
        // starts at kSettle, so a flight that starts airborne is settled at once
        if (!airborne) air_run_ = 0;
        else if (air_run_ <= HoverLimits::kSettle) ++air_run_;
        const bool ok = air_run_ > HoverLimits::kSettle && finite && std::fabs(vz) <= HoverLimits::kVzMax &&
                        std::fabs(roll) <= HoverLimits::kTiltMax && std::fabs(pitch) <= HoverLimits::kTiltMax &&
                        c >= HoverLimits::kCmdMin;
        if (!ok) {
            run_ = 0;
            return false;
        }
        cmd_ring_[head_] = c;
        cur_ring_[head_] = current;
        head_ = (head_ + 1) % N;
        if (++run_ < N) return false;
        float sc = 0.0f, si = 0.0f;  // oldest first: the ring's head is the oldest of the last N
        for (int k = 0; k < N; ++k) {
            const int j = (head_ + k) % N;
            sc += cmd_ring_[j];
            si += cur_ring_[j];
        }
        cmd_ = sc / static_cast<float>(N);
        cur_ = si / static_cast<float>(N);
        freeze_ = i;
        frozen_ = true;
        return true;
    }
    // ``m`` samples without data (NaN) at the airborne flag ``airborne`` (a gap in a stream), in O(1): the
    // state m push()es of them leave (the index advances, the steady run restarts, the airborne count
    // goes on or restarts). 0 <= m <= 2^62 - index() (fwref/stream.hpp bounds it).
    void skip(int64_t m, bool airborne) {
        if (m <= 0) return;
        index_ += m;
        if (frozen_) return;
        if (!airborne) air_run_ = 0;
        else air_run_ = m > HoverLimits::kSettle + 1 - air_run_ ? HoverLimits::kSettle + 1 : air_run_ + int(m);
        run_ = 0;
    }
    void reset() { *this = HoverEstimator(); }
    bool frozen() const { return frozen_; }
    float cmd() const { return cmd_; }
    float cur() const { return cur_; }
    int64_t freeze_index() const { return freeze_; }  // -1 until frozen
    int64_t index() const { return index_; }          // samples fed (push and skip)

private:
    float cmd_ring_[N] = {};
    float cur_ring_[N] = {};
    int head_ = 0;
    int run_ = 0;
    int64_t index_ = 0;
    int air_run_ = HoverLimits::kSettle;
    int64_t freeze_ = -1;
    bool frozen_ = false;
    float cmd_ = NAN;
    float cur_ = NAN;
};

}  // namespace fwref
