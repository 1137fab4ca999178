// tools/fwref_contracts.cpp -- scope: print the contracts this build has compiled in, one per line,
// so that a test can compare them with the Python tables they were generated from
// (formats/weights_layout.py, core/contracts.py). The weights.bin tensors are printed by visiting
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
#include <cstdio>
#include <string>

#include "fwref/contracts_gen.hpp"
#include "fwref/parity.hpp"
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
  return 0;
}
