// src/weights_file.cpp -- scope: binding weights.bin's sections to model structs with every
// tensor's dtype, shape and scales checked (fwref/weights_file.hpp). One binder serves the four
// model structs: which tensors a section holds, in which order, with which shapes, is the
// generated table fwref/weights_layout_gen.hpp (from formats/weights_layout.py), and its visit()
// hands each struct member to the binder with its tensor's spec.
#include "fwref/weights_file.hpp"

#include <cstdint>

#include <cstdio>
#include <utility>

#include "fwref/read_limits.hpp"

#include "fwref/weights_layout_gen.hpp"

namespace fwref {

namespace {

std::string shape_text(const int* shape, int ndim) {
  std::string s = "(";
  for (int i = 0; i < ndim; ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  return s + (ndim == 1 ? ",)" : ")");
}

}  // namespace

// Looks tensors up in one section, checks them against their spec and copies them into the
// WeightsFile's storage. The member's type says what the C++ side needs (MatQ: int8 with one scale
// per row; MatF, const float*, float: float32; const int32_t*: int32). The first failure sticks:
// later calls leave their member alone and the caller reports status().
class Binder {
 public:
  Binder(WeightsFile& wf, const SectionInfo& sec, std::string* error) : wf_(wf), sec_(sec), error_(error) {}

  Status status() const { return status_; }

  void operator()(const float*& out, const layout::TensorSpec& spec) {
    if (const TensorInfo* t = get(spec, DType::kF32, false)) out = f32(*t);
  }

  void operator()(float& out, const layout::TensorSpec& spec) {
    if (const TensorInfo* t = get(spec, DType::kF32, false)) out = *f32(*t);
  }

  void operator()(const std::int32_t*& out, const layout::TensorSpec& spec) {
    const TensorInfo* t = get(spec, DType::kI32, false);
    if (t == nullptr) return;
    wf_.i32_.emplace_back(t->count);
    wf_.file_.copy_i32(*t, wf_.i32_.back().data());
    out = wf_.i32_.back().data();
  }

  void operator()(MatF& out, const layout::TensorSpec& spec) {
    if (const TensorInfo* t = get(spec, DType::kF32, false)) out = MatF{f32(*t), t->shape[0], t->shape[1]};
  }

  void operator()(MatQ& out, const layout::TensorSpec& spec) {
    const TensorInfo* t = get(spec, DType::kI8, true);
    if (t == nullptr) return;
    for (int i = 0; i < t->n_scales; ++i) {
      if (wf_.file_.zero_point(*t, i) != 0) {
        fail(Status::kBadWeights, fmt("%s: tensor '%s' of section %s has a non-zero zero point (the int8 scheme "
                                      "is symmetric)", wf_.file_.where().c_str(), spec.name, sec_.label().c_str()));
        return;
      }
    }
    wf_.i8_.emplace_back(t->count);
    wf_.file_.copy_i8(*t, wf_.i8_.back().data());
    wf_.f32_.emplace_back(static_cast<std::size_t>(t->n_scales));
    wf_.file_.copy_scales(*t, wf_.f32_.back().data());
    out = MatQ{wf_.i8_.back().data(), wf_.f32_.back().data(), t->shape[0], t->shape[1]};
  }

  // In the file for other readers: checked, not kept.
  void operator()(layout::Unbound, const layout::TensorSpec& spec) {
    get(spec, spec.kind == layout::Kind::kIndex ? DType::kI32 : DType::kF32, false);
  }

  void fail(Status s, const std::string& message) {
    if (status_ != Status::kOk) return;
    status_ = s;
    *error_ = message;
  }

 private:
  // Each float32 tensor's copy starts on a 64-byte boundary (15 floats of slack): a matrix whose rows
  // are a multiple of 8 floats then never has a 32-byte load of the host fp32 gemv straddle two cache
  // lines (docs/bench.md: CNODE fp32 8.8 -> 7.4 us). The values are the same, so are the results.
  const float* f32(const TensorInfo& t) {
    wf_.f32_.emplace_back(t.count + 15);
    const std::uintptr_t a = reinterpret_cast<std::uintptr_t>(wf_.f32_.back().data());  // 4-byte aligned
    float* p = wf_.f32_.back().data() + ((64 - a % 64) % 64) / sizeof(float);
    wf_.file_.copy_f32(t, p);
    return p;
  }

  const TensorInfo* get(const layout::TensorSpec& spec, DType dtype, bool per_row) {
    if (status_ != Status::kOk) return nullptr;
    const TensorInfo* t = sec_.find(spec.name);
    if (t == nullptr) {
      fail(Status::kMissingTensor, fmt("%s: section %s lacks tensor '%s' (re-run `quadfdi export`)",
                                       wf_.file_.where().c_str(), sec_.label().c_str(), spec.name));
      return nullptr;
    }
    int shape[2];
    bool same = t->dtype == dtype && t->ndim == spec.ndim;
    for (int i = 0; i < spec.ndim; ++i) {
      shape[i] = layout::extent(spec.shape[i], sec_.dims);
      same = same && t->shape[i] == shape[i];
    }
    if (!same) {
      fail(Status::kBadShape, fmt("%s: tensor '%s' of section %s is %s %s, expected %s %s %s",
                                  wf_.file_.where().c_str(), spec.name, sec_.label().c_str(), dtype_name(t->dtype),
                                  t->shape_text().c_str(), dtype_name(dtype), shape_text(shape, spec.ndim).c_str(),
                                  spec.shape_text));
      return nullptr;
    }
    if (per_row && (t->axis != 0 || t->n_scales != t->shape[0])) {
      fail(Status::kBadShape, fmt("%s: tensor '%s' of section %s has %d scale(s) on axis %d, expected one per row",
                                  wf_.file_.where().c_str(), spec.name, sec_.label().c_str(), t->n_scales, t->axis));
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

// The section header's dims, each checked against this build's maximum or against the formula
// that derives it, before any of them sizes anything.
Status check_dims(const Container& file, const SectionInfo& sec, const layout::DimSpec* dims, int n,
                  std::string* error) {
  for (int i = 0; i < n; ++i) {
    const layout::DimSpec& d = dims[i];
    const std::uint32_t v = sec.dims[d.index];
    if (d.from >= 0) {
      const std::uint32_t want = std::uint32_t(d.a) * sec.dims[d.from] + std::uint32_t(d.b);
      if (v != want) {
        *error = fmt("%s: section %s has %s %s = %u, expected %d%s + %d = %u", file.where().c_str(),
                     sec.label().c_str(), d.what, d.symbol, v, d.a, dims[d.from].symbol, d.b, want);
        return Status::kDimsInvalid;
      }
    } else if (v == 0) {
      *error = fmt("%s: section %s has %s 0", file.where().c_str(), sec.label().c_str(), d.what);
      return Status::kDimsInvalid;
    } else if (v > static_cast<std::uint32_t>(d.limit)) {
      *error = fmt("%s: section %s has %s %u, this build's maximum is %d (%s in fwref/config.hpp)",
                   file.where().c_str(), sec.label().c_str(), d.what, v, d.limit, d.macro);
      return Status::kDimsTooLarge;
    }
  }
  return Status::kOk;
}

}  // namespace

template <class Model>
Status WeightsFile::bind_section(Model* m, std::string* error) {
  return bind_as(m, layout::Section<Model>::model, layout::Section<Model>::label, error);
}

// Section (model, the struct's precision) bound to the struct's layout: model is the struct's own
// code, or kModelSgru for the streaming GRU (the GRU's layout).
template <class Model>
Status WeightsFile::bind_as(Model* m, std::uint32_t model, const char* label, std::string* error) {
  using S = layout::Section<Model>;
  const SectionInfo* sec = file_.find(model, S::precision);
  if (sec == nullptr) {
    *error = fmt("%s holds no %s section", file_.where().c_str(), label);
    return Status::kMissingSection;
  }
  const Status s = check_dims(file_, *sec, S::dims, S::dim_count, error);
  if (s != Status::kOk) return s;
  layout::dims_from(sec->dims, &m->dims);
  Binder b(*this, *sec, error);
  layout::visit(*m, b);
  if (b.status() != Status::kOk) return b.status();
  const Status c = check(*m);
  if (c != Status::kOk) {
    *error = fmt("%s: section %s fails its consistency check: %s", file_.where().c_str(), sec->label().c_str(),
                 status_name(c));
  }
  return c;
}

Status WeightsFile::load(const std::string& path, std::string* error) {
  f32_.clear();
  i8_.clear();
  i32_.clear();
  return file_.load(path, layout::kMagic, layout::kVersion, "weights file", limits::kWeightsFileBytes, error);
}

Status WeightsFile::load_bytes(std::vector<unsigned char> bytes, const std::string& path, std::string* error) {
  f32_.clear();
  i8_.clear();
  i32_.clear();
  return file_.parse_bytes(std::move(bytes), path, layout::kMagic, layout::kVersion, "weights file", error);
}

Status WeightsFile::bind(CnodeF32* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(CnodeI8* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(GruF32* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(GruI8* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(CnodeMotorF32* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(CnodeMotorI8* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(GruMotorF32* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind(GruMotorI8* m, std::string* error) { return bind_section(m, error); }
Status WeightsFile::bind_sgru(GruF32* m, std::string* error) { return bind_as(m, kModelSgru, "sgru fp32", error); }
Status WeightsFile::bind_sgru(GruI8* m, std::string* error) { return bind_as(m, kModelSgru, "sgru int8", error); }

}  // namespace fwref
