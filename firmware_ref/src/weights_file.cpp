// src/weights_file.cpp -- scope: binding weights.bin's sections to model structs with every
// tensor's dtype, shape and scales checked (fwref/weights_file.hpp).
#include "fwref/weights_file.hpp"

#include <cstdarg>
#include <cstdio>

namespace fwref {

namespace {

std::string fmt(const char* f, ...) __attribute__((format(printf, 1, 2)));
std::string fmt(const char* f, ...) {
  char buf[512];
  va_list ap;
  va_start(ap, f);
  std::vsnprintf(buf, sizeof buf, f, ap);
  va_end(ap);
  return buf;
}

std::string shape_text(std::initializer_list<int> shape) {
  std::string s = "(";
  int i = 0;
  for (int d : shape) s += (i++ ? ", " : "") + std::to_string(d);
  return s + (shape.size() == 1 ? ",)" : ")");
}

}  // namespace

// Looks tensors up in one section, checks them and copies them into the WeightsFile's storage.
// The first failure sticks: later calls return placeholders and the caller reports status().
class Binder {
 public:
  Binder(WeightsFile& wf, const SectionInfo& sec, std::string* error) : wf_(wf), sec_(sec), error_(error) {}

  Status status() const { return status_; }

  const float* f32(const char* name, std::initializer_list<int> shape) {
    const TensorInfo* t = get(name, DType::kF32, shape, false);
    if (t == nullptr) return nullptr;
    wf_.f32_.emplace_back(t->count);
    wf_.file_.copy_f32(*t, wf_.f32_.back().data());
    return wf_.f32_.back().data();
  }

  float scalar(const char* name) {
    const float* p = f32(name, {1});
    return p == nullptr ? 0.0f : *p;
  }

  const std::int32_t* i32(const char* name, std::initializer_list<int> shape) {
    const TensorInfo* t = get(name, DType::kI32, shape, false);
    if (t == nullptr) return nullptr;
    wf_.i32_.emplace_back(t->count);
    wf_.file_.copy_i32(*t, wf_.i32_.back().data());
    return wf_.i32_.back().data();
  }

  MatF matf(const char* name, int rows, int cols) { return MatF{f32(name, {rows, cols}), rows, cols}; }

  MatQ matq(const char* name, int rows, int cols) {
    const TensorInfo* t = get(name, DType::kI8, {rows, cols}, true);
    if (t == nullptr) return MatQ{nullptr, nullptr, rows, cols};
    for (int i = 0; i < t->n_scales; ++i) {
      if (wf_.file_.zero_point(*t, i) != 0) {
        fail(Status::kBadWeights, fmt("%s: tensor '%s' of section %s has a non-zero zero point (the int8 scheme "
                                      "is symmetric)", wf_.file_.where().c_str(), name, sec_.label().c_str()));
        return MatQ{nullptr, nullptr, rows, cols};
      }
    }
    wf_.i8_.emplace_back(t->count);
    wf_.file_.copy_i8(*t, wf_.i8_.back().data());
    wf_.f32_.emplace_back(static_cast<std::size_t>(t->n_scales));
    wf_.file_.copy_scales(*t, wf_.f32_.back().data());
    return MatQ{wf_.i8_.back().data(), wf_.f32_.back().data(), rows, cols};
  }

  void fail(Status s, const std::string& message) {
    if (status_ != Status::kOk) return;
    status_ = s;
    *error_ = message;
  }

 private:
  const TensorInfo* get(const char* name, DType dtype, std::initializer_list<int> shape, bool per_row) {
    if (status_ != Status::kOk) return nullptr;
    const TensorInfo* t = sec_.find(name);
    if (t == nullptr) {
      fail(Status::kMissingTensor, fmt("%s: section %s lacks tensor '%s' (re-run `quadfdi export`)",
                                       wf_.file_.where().c_str(), sec_.label().c_str(), name));
      return nullptr;
    }
    bool same = t->dtype == dtype && t->ndim == static_cast<int>(shape.size());
    int i = 0;
    for (int d : shape) same = same && t->shape[i++] == d;
    if (!same) {
      fail(Status::kBadShape, fmt("%s: tensor '%s' of section %s is %s %s, expected %s %s", wf_.file_.where().c_str(),
                                  name, sec_.label().c_str(), dtype_name(t->dtype), t->shape_text().c_str(),
                                  dtype_name(dtype), shape_text(shape).c_str()));
      return nullptr;
    }
    if (per_row && (t->axis != 0 || t->n_scales != t->shape[0])) {
      fail(Status::kBadShape, fmt("%s: tensor '%s' of section %s has %d scale(s) on axis %d, expected one per row",
                                  wf_.file_.where().c_str(), name, sec_.label().c_str(), t->n_scales, t->axis));
      return nullptr;
    }
    return t;
  }

  WeightsFile& wf_;
  const SectionInfo& sec_;
  std::string* error_;
  Status status_ = Status::kOk;
};

namespace {

struct Limit {
  const char* name;
  std::uint32_t value;
  int max;
  const char* macro;
};

// Dimensions from the section header, each checked against this build's maximum before use.
Status check_limits(const Container& file, const SectionInfo& sec, std::initializer_list<Limit> limits,
                    std::string* error) {
  for (const Limit& l : limits) {
    if (l.value == 0) {
      *error = fmt("%s: section %s has %s 0", file.where().c_str(), sec.label().c_str(), l.name);
      return Status::kDimsInvalid;
    }
    if (l.value > static_cast<std::uint32_t>(l.max)) {
      *error = fmt("%s: section %s has %s %u, this build's maximum is %d (%s in fwref/config.hpp)",
                   file.where().c_str(), sec.label().c_str(), l.name, l.value, l.max, l.macro);
      return Status::kDimsTooLarge;
    }
  }
  return Status::kOk;
}

const SectionInfo* section_or_error(const Container& file, std::uint32_t model, std::uint32_t prec,
                                    std::string* error) {
  const SectionInfo* sec = file.find(model, prec);
  if (sec == nullptr) {
    *error = fmt("%s holds no %s %s section", file.where().c_str(), model_name(model), precision_name(prec));
  }
  return sec;
}

Status cnode_dims(const Container& file, const SectionInfo& sec, CnodeDims* d, std::string* error) {
  const std::uint32_t* v = sec.dims;
  Status s = check_limits(file, sec,
                          {{"channels", v[0], kMaxChannels, "FWREF_MAX_CHANNELS"},
                           {"window", v[1], kMaxWindow, "FWREF_MAX_WINDOW"},
                           {"classes", v[2], kMaxClasses, "FWREF_MAX_CLASSES"},
                           {"hidden", v[3], kMaxCnodeHidden, "FWREF_MAX_CNODE_HIDDEN"},
                           {"latent", v[4], kMaxLatent, "FWREF_MAX_LATENT"},
                           {"steps N", v[5], kMaxSteps, "FWREF_MAX_STEPS"}},
                          error);
  if (s != Status::kOk) return s;
  if (v[6] != 2 * v[5] + 1) {
    *error = fmt("%s: section %s has %u stage times for N = %u steps, classic RK4 has 2N + 1 = %u",
                 file.where().c_str(), sec.label().c_str(), v[6], v[5], 2 * v[5] + 1);
    return Status::kDimsInvalid;
  }
  *d = CnodeDims{int(v[0]), int(v[1]), int(v[2]), int(v[3]), int(v[4]), int(v[5]), int(v[6])};
  return Status::kOk;
}

Status gru_dims(const Container& file, const SectionInfo& sec, GruDims* d, std::string* error) {
  const std::uint32_t* v = sec.dims;
  Status s = check_limits(file, sec,
                          {{"channels", v[0], kMaxChannels, "FWREF_MAX_CHANNELS"},
                           {"window", v[1], kMaxWindow, "FWREF_MAX_WINDOW"},
                           {"classes", v[2], kMaxClasses, "FWREF_MAX_CLASSES"},
                           {"hidden", v[3], kMaxGruHidden, "FWREF_MAX_GRU_HIDDEN"}},
                          error);
  if (s != Status::kOk) return s;
  *d = GruDims{int(v[0]), int(v[1]), int(v[2]), int(v[3])};
  return Status::kOk;
}

template <class Model>
Status finish(const Binder& b, const Container& file, const SectionInfo& sec, const Model& m, std::string* error) {
  if (b.status() != Status::kOk) return b.status();
  const Status s = check(m);
  if (s != Status::kOk) {
    *error = fmt("%s: section %s fails its consistency check: %s", file.where().c_str(), sec.label().c_str(),
                 status_name(s));
  }
  return s;
}

}  // namespace

Status WeightsFile::load(const std::string& path, std::string* error) {
  f32_.clear();
  i8_.clear();
  i32_.clear();
  return file_.load(path, kWeightsMagic, kWeightsVersion, "weights file", error);
}

Status WeightsFile::bind(CnodeF32* m, std::string* error) {
  const SectionInfo* sec = section_or_error(file_, kModelCnode, kPrecF32, error);
  if (sec == nullptr) return Status::kMissingSection;
  Status s = cnode_dims(file_, *sec, &m->dims, error);
  if (s != Status::kOk) return s;
  const CnodeDims& d = m->dims;
  const int C = d.channels, W = d.window, K = d.classes, H = d.hidden, L = d.latent, S = d.stage_times;
  Binder b(*this, *sec, error);
  m->mean = b.f32("norm.mean", {C});
  m->std = b.f32("norm.std", {C});
  m->interp = b.matf("interp", S, W);
  m->stage_index = b.i32("stage_index", {d.evals()});
  m->rk4 = b.f32("rk4.consts", {kRk4Consts});
  m->encoder_w = b.matf("encoder.weight", L, C);
  m->encoder_b = b.f32("encoder.bias", {L});
  m->lin1_z = b.matf("lin1_z.weight", H, L);
  m->lin1_u = b.matf("lin1_u.weight", H, C);
  m->lin1_b = b.f32("lin1.bias", {H});
  m->lin2_w = b.matf("lin2.weight", L, H);
  m->lin2_b = b.f32("lin2.bias", {L});
  m->head_w = b.matf("head.weight", K, L);
  m->head_b = b.f32("head.bias", {K});
  return finish(b, file_, *sec, *m, error);
}

Status WeightsFile::bind(CnodeI8* m, std::string* error) {
  const SectionInfo* sec = section_or_error(file_, kModelCnode, kPrecI8, error);
  if (sec == nullptr) return Status::kMissingSection;
  Status s = cnode_dims(file_, *sec, &m->dims, error);
  if (s != Status::kOk) return s;
  const CnodeDims& d = m->dims;
  const int C = d.channels, W = d.window, K = d.classes, H = d.hidden, L = d.latent, S = d.stage_times;
  Binder b(*this, *sec, error);
  m->mean = b.f32("norm.mean", {C});
  m->std = b.f32("norm.std", {C});
  m->interp = b.matq("interp", S, W);
  m->stage_index = b.i32("stage_index", {d.evals()});
  m->rk4 = b.f32("rk4.consts", {kRk4Consts});
  m->encoder_w = b.matq("encoder.weight", L, C);
  m->encoder_b = b.f32("encoder.bias", {L});
  m->lin1_z = b.matq("lin1_z.weight", H, L);
  m->lin1_u = b.matq("lin1_u.weight", H, C);
  m->lin1_b = b.f32("lin1.bias", {H});
  m->lin2_w = b.matq("lin2.weight", L, H);
  m->lin2_b = b.f32("lin2.bias", {L});
  m->head_w = b.matq("head.weight", K, L);
  m->head_b = b.f32("head.bias", {K});
  m->s_x = b.f32("act.x_norm.scale", {C});
  m->s_u = b.f32("act.u.scale", {C});
  m->s_stage = b.f32("act.stage.scale", {d.evals()});
  m->s_hidden = b.scalar("act.hidden.scale");
  m->s_z1 = b.scalar("act.z1.scale");
  return finish(b, file_, *sec, *m, error);
}

Status WeightsFile::bind(GruF32* m, std::string* error) {
  const SectionInfo* sec = section_or_error(file_, kModelGru, kPrecF32, error);
  if (sec == nullptr) return Status::kMissingSection;
  Status s = gru_dims(file_, *sec, &m->dims, error);
  if (s != Status::kOk) return s;
  const int C = m->dims.channels, K = m->dims.classes, H = m->dims.hidden;
  Binder b(*this, *sec, error);
  m->mean = b.f32("norm.mean", {C});
  m->std = b.f32("norm.std", {C});
  m->w_ih = b.matf("gru.weight_ih", 3 * H, C);
  m->w_hh = b.matf("gru.weight_hh", 3 * H, H);
  m->b_ih = b.f32("gru.bias_ih", {3 * H});
  m->b_hh = b.f32("gru.bias_hh", {3 * H});
  m->head_w = b.matf("head.weight", K, H);
  m->head_b = b.f32("head.bias", {K});
  return finish(b, file_, *sec, *m, error);
}

Status WeightsFile::bind(GruI8* m, std::string* error) {
  const SectionInfo* sec = section_or_error(file_, kModelGru, kPrecI8, error);
  if (sec == nullptr) return Status::kMissingSection;
  Status s = gru_dims(file_, *sec, &m->dims, error);
  if (s != Status::kOk) return s;
  const int C = m->dims.channels, K = m->dims.classes, H = m->dims.hidden;
  Binder b(*this, *sec, error);
  m->mean = b.f32("norm.mean", {C});
  m->std = b.f32("norm.std", {C});
  m->w_ih = b.matq("gru.weight_ih", 3 * H, C);
  m->w_hh = b.matq("gru.weight_hh", 3 * H, H);
  m->b_ih = b.f32("gru.bias_ih", {3 * H});
  m->b_hh = b.f32("gru.bias_hh", {3 * H});
  m->head_w = b.matq("head.weight", K, H);
  m->head_b = b.f32("head.bias", {K});
  m->s_x = b.f32("act.x_norm.scale", {C});
  m->s_h = b.scalar("act.h.scale");
  return finish(b, file_, *sec, *m, error);
}

}  // namespace fwref
