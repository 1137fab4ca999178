// src/onboard.cpp -- scope: reading and checking weights.bin's on-board record (fwref/onboard.hpp).
#include "fwref/onboard.hpp"

#include <cstring>

namespace fwref {

namespace {

constexpr const char* kTensors[] = {"raw.names", "model.names", "sample_dt_s", "hover.limits", "alarm.threshold",
                                    "alarm.policy"};

std::vector<std::string> names_of(const std::vector<std::int32_t>& codes) {
  std::vector<std::string> out;
  std::string cur;
  for (std::int32_t c : codes) {
    if (c == 0) {
      out.push_back(cur);
      cur.clear();
    } else {
      cur += static_cast<char>(c);
    }
  }
  return out;
}

double threshold_of(std::int32_t lo, std::int32_t hi) {
  std::uint64_t bits = std::uint32_t(lo) | (std::uint64_t(std::uint32_t(hi)) << 32);
  double threshold;
  std::memcpy(&threshold, &bits, sizeof threshold);
  return threshold;
}

// A policy core.alarm.check_policy accepts: 0 < threshold <= 1, 1 <= k <= n, clear_m >= 1; latch 0 or 1.
bool valid_policy(const AlarmParams& a, std::int32_t latch) {
  return latch >= 0 && latch <= 1 && a.k >= 1 && a.k <= a.n && a.clear_m >= 1 && a.threshold > 0.0 &&
         a.threshold <= 1.0;
}

// alarm.models (optional): int32 (M, kAlarmModelsWidth) rows in contracts_gen.hpp's column order (model
// code, k, n, clear_m, latch, threshold lo, hi); each model a network with a policy of its own
// (policy_network), at most once; each row a valid policy (core.alarm.check_policy).
Status read_policies(const Container& file, const SectionInfo& sec, const AlarmParams& base, OnboardRecord* r,
                     std::string* error) {
  r->model_policies.clear();
  const TensorInfo* t = sec.find("alarm.models");
  if (t == nullptr) return Status::kOk;
  namespace c = contracts;
  if (t->dtype != DType::kI32 || t->ndim != 2 || t->shape[1] != c::kAlarmModelsWidth || t->shape[0] > 8) {
    *error = fmt("%s: the on-board record's alarm.models is not int32 (M, %d) with M <= 8", file.where().c_str(),
                 c::kAlarmModelsWidth);
    return Status::kBadShape;
  }
  std::vector<std::int32_t> v(t->count);
  file.copy_i32(*t, v.data());
  for (int i = 0; i < t->shape[0]; ++i) {
    const std::int32_t* row = &v[std::size_t(i) * c::kAlarmModelsWidth];
    const std::uint32_t model = std::uint32_t(row[c::kAlarmModelsModel]);
    AlarmParams a = base;
    a.threshold = threshold_of(row[c::kAlarmModelsThresholdLo], row[c::kAlarmModelsThresholdHi]);
    a.k = row[c::kAlarmModelsK], a.n = row[c::kAlarmModelsN], a.clear_m = row[c::kAlarmModelsClearM];
    const std::int32_t latch = row[c::kAlarmModelsLatch];
    a.latch = latch != 0;
    bool known = policy_network(model);
    for (const OnboardRecord::ModelPolicy& seen : r->model_policies) known = known && seen.model != model;
    if (!known || !valid_policy(a, latch)) {
      *error = fmt("%s: the on-board record's alarm.models row %d (model %d) is not a valid policy of a distinct "
                   "model", file.where().c_str(), i, int(model));
      return Status::kDimsInvalid;
    }
    r->model_policies.push_back({model, a});
  }
  return Status::kOk;
}

}  // namespace

AlarmParams policy_for(const OnboardRecord& r, std::uint32_t model, bool* from_table) {
  for (const OnboardRecord::ModelPolicy& p : r.model_policies) {
    if (p.model == model) {
      if (from_table != nullptr) *from_table = true;
      return p.alarm;
    }
  }
  if (from_table != nullptr) *from_table = false;
  return r.params.alarm;
}

Status read_onboard(const WeightsFile& wf, OnboardRecord* out, std::string* error) {
  const Container& file = wf.container();
  const SectionInfo* sec = file.find(kModelNone, kPrecNone);
  if (sec == nullptr) {
    *error = fmt("%s holds no on-board record (written before it: re-run `quadfdi export`)", file.where().c_str());
    return Status::kMissingSection;
  }
  const TensorInfo* t[6];
  for (int i = 0; i < 6; ++i) {
    t[i] = sec->find(kTensors[i]);
    const bool f32 = i == 2 || i == 3;
    if (t[i] == nullptr || t[i]->dtype != (f32 ? DType::kF32 : DType::kI32) || t[i]->ndim != 1) {
      *error = fmt("%s: the on-board record lacks tensor '%s' or it has the wrong dtype", file.where().c_str(),
                   kTensors[i]);
      return Status::kBadShape;
    }
  }
  std::vector<std::int32_t> raw(t[0]->count), model(t[1]->count), thr(2), pol(contracts::kAlarmPolicyWidth);
  float dt = 0.0f;
  if (t[2]->count != 1 || t[3]->count != 3 || t[4]->count != 2 || t[5]->count != pol.size()) {
    *error = fmt("%s: the on-board record's tensors have the wrong sizes", file.where().c_str());
    return Status::kBadShape;
  }
  file.copy_i32(*t[0], raw.data());
  file.copy_i32(*t[1], model.data());
  file.copy_f32(*t[2], &dt);
  file.copy_f32(*t[3], out->hover_limits);
  file.copy_i32(*t[4], thr.data());
  file.copy_i32(*t[5], pol.data());
  const std::uint32_t* d = sec->dims;
  OnboardRecord& r = *out;
  r.raw_names = names_of(raw);
  r.model_names = names_of(model);
  if (d[0] >= static_cast<std::uint32_t>(kProfileCount) || r.raw_names.size() != d[3] || r.model_names.size() != d[4]) {
    *error = fmt("%s: the on-board record's dims disagree with its channel names (profile id %u)", file.where().c_str(),
                 d[0]);
    return Status::kDimsInvalid;
  }
  const double threshold = threshold_of(thr[0], thr[1]);
  std::uint32_t mask = 0xFFFFFFFFu;  // no alarm.rotor_side (a record written before it): every class
  r.rotor_classes = 0;
  if (const TensorInfo* rs = sec->find("alarm.rotor_side")) {
    if (rs->dtype != DType::kI32 || rs->ndim != 1 || rs->count < 2 || rs->count > 32) {
      *error = fmt("%s: the on-board record's alarm.rotor_side is not int32 (K,) with 2 <= K <= 32", file.where().c_str());
      return Status::kBadShape;
    }
    std::vector<std::int32_t> flags(rs->count);
    file.copy_i32(*rs, flags.data());
    mask = 0;
    for (std::size_t c = 0; c < flags.size(); ++c) {
      if (flags[c] != 0 && flags[c] != 1) {
        *error = fmt("%s: the on-board record's alarm.rotor_side holds %d (0/1 expected)", file.where().c_str(),
                     int(flags[c]));
        return Status::kDimsInvalid;
      }
      mask |= std::uint32_t(flags[c]) << c;
    }
    r.rotor_classes = int(rs->count);
  }
  namespace c = contracts;
  AlarmParams alarm{threshold, pol[c::kAlarmPolicyK], pol[c::kAlarmPolicyN], pol[c::kAlarmPolicyClearM],
                    pol[c::kAlarmPolicyLatch] != 0, pol[c::kAlarmPolicyHealthy], 0, mask};
  if (!valid_policy(alarm, pol[c::kAlarmPolicyLatch])) {
    *error = fmt("%s: the on-board record's alarm.policy (threshold %g, k %d, n %d, clear_m %d, latch %d) is not a "
                 "valid policy", file.where().c_str(), threshold, alarm.k, alarm.n, alarm.clear_m,
                 int(pol[c::kAlarmPolicyLatch]));
    return Status::kDimsInvalid;
  }
  r.params = StreamParams{static_cast<Profile>(d[0]), int(d[1]), int(d[2]), int(d[3]), int(d[4]), 0, double(dt), alarm};
  const Status pol_status = read_policies(file, *sec, r.params.alarm, &r, error);
  if (pol_status != Status::kOk) return pol_status;
  r.cells_from_stream = d[5] != 0;
  r.hover_steady = int(d[6]);
  r.hover_settle = int(d[7]);
  const ProfileSpec& spec = profile_spec(r.params.profile);
  if (r.params.profile != Profile::kPaper) {
    for (int i = 0; i < spec.raw; ++i) {
      if (int(r.raw_names.size()) != spec.raw || r.raw_names[i] != spec.raw_names[i]) {
        *error = fmt("%s: the on-board record's raw channels are not profile %s's as this build knows them",
                     file.where().c_str(), spec.name);
        return Status::kDimsInvalid;
      }
    }
    for (int i = 0; i < spec.channels; ++i) {
      if (int(r.model_names.size()) != spec.channels || r.model_names[i] != spec.model_names[i]) {
        *error = fmt("%s: the on-board record's model channels are not profile %s's", file.where().c_str(), spec.name);
        return Status::kDimsInvalid;
      }
    }
    if (r.hover_steady != kHoverSteady || r.hover_settle != HoverLimits::kSettle ||
        r.hover_limits[0] != HoverLimits::kVzMax || r.hover_limits[1] != HoverLimits::kTiltMax ||
        r.hover_limits[2] != HoverLimits::kCmdMin) {
      *error = fmt("%s: the on-board record's hover constants (%d, %d, %g, %g, %g) are not this build's "
                   "(fwref/hover.hpp)", file.where().c_str(), r.hover_steady, r.hover_settle, r.hover_limits[0],
                   r.hover_limits[1], r.hover_limits[2]);
      return Status::kDimsInvalid;
    }
  }
  return Status::kOk;
}

}  // namespace fwref
