// tools/fwref_contracts.cpp -- scope: print the contracts this build has compiled in, one per line,
// so that a test can compare them with the Python tables they were generated from
// (formats/weights_layout.py, core/contracts.py, core/channels.py). The weights.bin tensors are printed by visiting
// each model struct: the dtype comes from the struct member's type, so the line says what the C++
// binder will require, not merely what the generated table says.
//
//   fwref_contracts
//
// Lines:
//   weights <magic> <version> | reference <magic> <version>
//   section <model> <precision>
//   dim <symbol> <index> limit <macro> | dim <symbol> <index> = <a><symbol> + <b>
//   tensor <name> <float32|int8|int32> <shape formula, e.g. (3H,C)>
//   class <label> <name> | split <name> <code> | tolerance <name> <value> | rk4 <index> <name>
//   known_class <index> <name> rotor <0|1> | model_code <code> <name> [policy] | policy_key <index> <name>
//   alarm_params <threshold> <k> <n> <clear_m> <latch>   (AlarmParams{0.25, 1, 2, 3, true} read back by name)
//   channel <id> <name> | profile <id> <name> raw <names,> model <names,>   (as fwref::profile_spec gives them)
#include <cstdio>
#include <string>

#include "fwref/alarm.hpp"
#include "fwref/contracts_gen.hpp"
#include "fwref/parity.hpp"
#include "fwref/profile.hpp"
#include "fwref/weights_layout_gen.hpp"

namespace {

using fwref::layout::TensorSpec;

template <class Model>
struct Printer {
  void line(const char* dtype, const TensorSpec& spec) {
    using S = fwref::layout::Section<Model>;
    std::string shape = "(";
    for (int i = 0; i < spec.ndim; ++i) {
      const fwref::layout::Extent& e = spec.shape[i];
      if (i) shape += ",";
      if (e.dim < 0) {
        shape += std::to_string(e.factor);
        continue;
      }
      if (e.factor != 1) shape += std::to_string(e.factor);
      for (int d = 0; d < S::dim_count; ++d) {
        if (S::dims[d].index == e.dim) shape += S::dims[d].symbol;
      }
    }
    std::printf("tensor %s %s %s)\n", spec.name, dtype, shape.c_str());
  }
  void operator()(const float*&, const TensorSpec& s) { line("float32", s); }
  void operator()(float&, const TensorSpec& s) { line("float32", s); }
  void operator()(const std::int32_t*&, const TensorSpec& s) { line("int32", s); }
  void operator()(fwref::MatF&, const TensorSpec& s) { line("float32", s); }
  void operator()(fwref::MatQ&, const TensorSpec& s) { line("int8", s); }
  void operator()(fwref::layout::Unbound, const TensorSpec& s) {
    line(s.kind == fwref::layout::Kind::kIndex ? "int32" : "float32", s);
  }
};

template <class Model>
void print_section() {
  using S = fwref::layout::Section<Model>;
  std::printf("section %s\n", S::label);
  for (int d = 0; d < S::dim_count; ++d) {
    const fwref::layout::DimSpec& x = S::dims[d];
    if (x.from >= 0) {
      std::printf("dim %s %d = %d%s + %d\n", x.symbol, x.index, x.a, S::dims[x.from].symbol, x.b);
    } else {
      std::printf("dim %s %d limit %s\n", x.symbol, x.index, x.macro);
    }
  }
  Model m{};
  Printer<Model> p;
  fwref::layout::visit(m, p);
}

std::string joined(const char* const* names, int n) {
  std::string out;
  for (int i = 0; i < n; ++i) out += (i ? "," : "") + std::string(names[i]);
  return out;
}

// The classes, section codes, policy keys, channels and profiles as the runtime compiles them in.
void print_tables() {
  namespace c = fwref::contracts;
  for (int k = 0; k < c::kNumKnownClasses; ++k) std::printf("known_class %d %s rotor %d\n", k, c::kKnownClassNames[k], int(c::kRotorSide[k]));
  for (std::uint32_t code = 0; code < 64; ++code) {
    if (fwref::model_code_name(code) == nullptr) continue;
    std::printf("model_code %u %s%s\n", code, fwref::model_code_name(code), fwref::policy_network(code) ? " policy" : "");
  }
  for (int i = 0; i < c::kPolicyKeyCount; ++i) std::printf("policy_key %d %s\n", i, c::kPolicyKeys[i]);
  const fwref::AlarmParams a{0.25, 1, 2, 3, true, 0, 4};
  std::printf("alarm_params %.17g %d %d %d %d\n", a.threshold, a.k, a.n, a.clear_m, int(a.latch));
  for (int i = 0; i < fwref::kChannelCount; ++i) std::printf("channel %d %s\n", i, fwref::kChannelNames[i]);
  for (int i = 0; i < fwref::kProfileCount; ++i) {
    const fwref::ProfileSpec& s = fwref::profile_spec(static_cast<fwref::Profile>(i));
    std::printf("profile %d %s raw %s model %s\n", i, s.name, joined(s.raw_names, s.raw).c_str(),
                joined(s.model_names, s.channels).c_str());
  }
}

}  // namespace

int main(int argc, char**) {
  if (argc > 1) {
    std::fprintf(stderr, "fwref_contracts: takes no arguments; usage: fwref_contracts\n");
    return 1;
  }
  namespace c = fwref::contracts;
  std::printf("weights %s %u\n", fwref::layout::kMagic, fwref::layout::kVersion);
  std::printf("reference %s %u\n", fwref::layout::kReferenceMagic, fwref::layout::kReferenceVersion);
  print_section<fwref::CnodeF32>();
  print_section<fwref::CnodeI8>();
  print_section<fwref::GruF32>();
  print_section<fwref::GruI8>();
  print_section<fwref::CnodeMotorF32>();  // the optional motor-head sections, in their file order
  print_section<fwref::CnodeMotorI8>();
  print_section<fwref::GruMotorF32>();
  print_section<fwref::GruMotorI8>();
  for (int k = 0; k < c::kNumClasses; ++k) std::printf("class %d %s\n", k, c::kClassNames[k]);
  std::printf("split train %d\nsplit validation %d\nsplit test %d\n", c::kSplitTrain, c::kSplitValidation,
              c::kSplitTest);
  std::printf("tolerance fp32_cpp_rel_tol %.17g\n", c::kFp32CppRelTol);
  std::printf("tolerance fp32_ort_vs_torch_rel_tol %.17g\n", c::kFp32OrtVsTorchRelTol);
  std::printf("tolerance int8_argmax_min %.17g\n", c::kInt8ArgmaxMin);
  std::printf("tolerance int8_tol_steps %.17g\n", c::kInt8TolSteps);
  std::printf("parity fp32 %.17g int8 %.17g\n", fwref::kF32RelTol, fwref::kI8TolSteps);
  for (int i = 0; i < c::kRk4NumConsts; ++i) std::printf("rk4 %d %s\n", i, c::kRk4ConstNames[i]);
  std::printf("rk4_consts_index %d %d %d %d\n", c::kRk4HalfH, c::kRk4H, c::kRk4Two, c::kRk4HOver6);
  print_tables();
  return 0;
}
