// fwref/config.hpp -- scope: the compile-time limits of the firmware reference (the largest model
// it accepts, which sizes every static buffer) and the static checks that keep its int8 arithmetic
// exact. Nothing here depends on a particular weights file.
//
// Host builds use the generous defaults below. The microcontroller build sets every limit to the
// exported model's own dimensions (quadfdi.runtimes.mcu_weights_src writes fwref_limits.h and the
// build passes -DFWREF_LIMITS_HEADER="fwref_limits.h"), so no RAM is spent on unused capacity.
#pragma once

#include <cstdint>

#include "fwref/contracts_gen.hpp"

#ifdef FWREF_LIMITS_HEADER
#include FWREF_LIMITS_HEADER
#endif

#ifndef FWREF_MAX_CHANNELS
#define FWREF_MAX_CHANNELS 64
#endif
#ifndef FWREF_MAX_WINDOW
#define FWREF_MAX_WINDOW 256
#endif
#ifndef FWREF_MAX_CLASSES
#define FWREF_MAX_CLASSES 16
#endif
#ifndef FWREF_MAX_LATENT
#define FWREF_MAX_LATENT 128
#endif
#ifndef FWREF_MAX_CNODE_HIDDEN
#define FWREF_MAX_CNODE_HIDDEN 256
#endif
#ifndef FWREF_MAX_STEPS
#define FWREF_MAX_STEPS 64
#endif
#ifndef FWREF_MAX_GRU_HIDDEN
#define FWREF_MAX_GRU_HIDDEN 256
#endif
#ifndef FWREF_MOTORS
#define FWREF_MOTORS 4
#endif

namespace fwref {

constexpr int kMaxChannels = FWREF_MAX_CHANNELS;        // C, telemetry channels
constexpr int kMaxWindow = FWREF_MAX_WINDOW;            // W, samples per window
constexpr int kMaxClasses = FWREF_MAX_CLASSES;          // K
constexpr int kMaxLatent = FWREF_MAX_LATENT;            // L, CNODE latent state
constexpr int kMaxCnodeHidden = FWREF_MAX_CNODE_HIDDEN; // H, width of the CNODE vector field
constexpr int kMaxSteps = FWREF_MAX_STEPS;              // N, classic RK4 steps
constexpr int kMaxStageTimes = 2 * kMaxSteps + 1;       // S = 2N + 1 distinct stage times
constexpr int kRk4StagesPerStep = contracts::kRk4StagesPerStep;  // field evaluations per step
constexpr int kRk4Consts = contracts::kRk4NumConsts;              // weights.bin's rk4.consts
constexpr int kMaxEvals = kRk4StagesPerStep * kMaxSteps; // 4N field evaluations
constexpr int kMaxGruHidden = FWREF_MAX_GRU_HIDDEN;     // GRU hidden state
constexpr int kMaxGruGates = 3 * kMaxGruHidden;         // r, z, n rows
constexpr int kMotors = FWREF_MOTORS;                   // outputs of the motor head (models.motor): one per rotor

// int8 products accumulate sum_i q[i] * Wq[o, i] in int32 with |q| <= 128 and |Wq| <= 127. The
// rescale converts the sum to float32, which is exact only below 2^24 (docs/formats.md):
// every inner dimension must keep |acc| < 2^24, i.e. at most 1031 terms.
constexpr long kExactFloatInt = 1L << 24;
constexpr long max_abs_acc(int terms) { return long(terms) * 127L * 128L; }
static_assert(max_abs_acc(kMaxWindow) < kExactFloatInt, "interp product could exceed 2^24");
static_assert(max_abs_acc(kMaxChannels) < kExactFloatInt, "encoder / lin1_u / W_ih product could exceed 2^24");
static_assert(max_abs_acc(kMaxLatent) < kExactFloatInt, "lin1_z / head product could exceed 2^24");
static_assert(max_abs_acc(kMaxCnodeHidden) < kExactFloatInt, "lin2 product could exceed 2^24");
static_assert(max_abs_acc(kMaxGruHidden) < kExactFloatInt, "W_hh / GRU head product could exceed 2^24");
static_assert(kMaxChannels > 0 && kMaxWindow > 1 && kMaxClasses > 0 && kMaxLatent > 0 && kMaxCnodeHidden > 0 &&
                  kMaxSteps > 0 && kMaxGruHidden > 0,
              "every limit must be positive");

}  // namespace fwref
