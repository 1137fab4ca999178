// fwref/onboard.hpp -- scope: weights.bin's on-board record on the host (formats/onboard.py,
// docs/formats.md): the section (model 0, precision 0) after the model sections, read and checked
// against this build: a hover profile's raw and model channels must be the ones fwref/profile.hpp
// compiles in (fwref/channels_gen.hpp, from core/channels.py), the hover filter's constants the ones
// fwref/hover.hpp compiles in. The policy tensors' columns and the model codes are contracts_gen.hpp's
// (core/contracts.py). Host only
// (std::string, std::vector); a microcontroller build takes the same values from generated constants.
#pragma once

#include <string>
#include <vector>

#include "fwref/stream.hpp"
#include "fwref/weights_file.hpp"

namespace fwref {

struct OnboardRecord {
  StreamParams params{};             // classes: 0 here, the bound model's K goes in before Stream::init
  bool cells_from_stream = false;    // the cell count comes with the stream (its header)
  int hover_steady = 0, hover_settle = 0;
  float hover_limits[3] = {};        // vz_max, tilt_max, cmd_min
  std::vector<std::string> raw_names;    // the stream's channels, in sample order
  std::vector<std::string> model_names;  // the model's input channels
  // Classes the record's alarm.rotor_side covers (params.alarm.rotor_mask holds the flags), 0 when the
  // record was written before that tensor (the mask is then every class: rule 4 alone). The bound
  // model's K must equal it when it is not 0.
  int rotor_classes = 0;
  // The record's alarm.models: one policy per network (a model code for which policy_network() holds;
  // threshold, k, n, clear_m, latch; healthy, classes and rotor_mask are params.alarm's). Empty in a
  // record written before the table: every model runs params.alarm.
  struct ModelPolicy {
    std::uint32_t model;
    AlarmParams alarm;
  };
  std::vector<ModelPolicy> model_policies;
};

// The policy of the model ``model`` (a section code of contracts_gen.hpp): its alarm.models row, else
// the record's single policy (params.alarm); ``*from_table`` (if given) says which. The rule of
// core.alarm.resolve_policy, which Python's formats.onboard.policy_of and the manifest reader use.
AlarmParams policy_for(const OnboardRecord& r, std::uint32_t model, bool* from_table = nullptr);

// kMissingSection: a weights.bin written before the record (re-run `quadfdi export`); kBadShape /
// kDimsInvalid: a record this build cannot run. ``*error`` is one line naming the file.
Status read_onboard(const WeightsFile& wf, OnboardRecord* out, std::string* error);

}  // namespace fwref
