// tools/fwref_activations.cpp -- scope: the library's tanh and logistic sigmoid on raw floats, so that
// tests can compare them with ONNX Runtime's Tanh and Sigmoid kernels bit for bit.
//
//   fwref_activations --in <x.f32> --out <y.f32>     y = (2, n) float32: tanh(x), then sigmoid(x)
//
// x.f32: a regular file of whole float32 values, at most limits::kToolInputBytes (fwref/read_limits.hpp).
// Usage error: exit 1; an input it cannot use or an output it cannot write: one line, exit 2, no output.
#include <string>
#include <vector>

#include "fwref/numerics.hpp"
#include "host_common.hpp"
#include "host_files.hpp"

int main(int argc, char** argv) try {
  if (argc != 5 || std::string(argv[1]) != "--in" || std::string(argv[3]) != "--out") {
    std::fprintf(stderr, "fwref_activations: usage: fwref_activations --in <x.f32> --out <y.f32>\n");
    return 1;
  }
  std::vector<unsigned char> bytes;
  std::string error;
  auto fail = [](const std::string& e) { return std::fprintf(stderr, "fwref_activations: error: %s\n", e.c_str()), 2; };
  if (!fwref::host::output_allowed(argv[4], {argv[2]}, {"--in file"}, &error)) return fail(error);
  if (!fwref::host::read_file(argv[2], "input", fwref::limits::kToolInputBytes, &bytes, &error)) return fail(error);
  if (bytes.size() % 4 != 0) return fail("input " + std::string(argv[2]) + " is not whole float32 values");
  const std::size_t n = bytes.size() / 4;
  std::vector<float> x(n), y(2 * n);
  std::memcpy(x.data(), bytes.data(), bytes.size());
  for (std::size_t i = 0; i < n; ++i) {
    y[i] = fwref::tanh_approx(x[i]);
    y[n + i] = fwref::logistic_approx(x[i]);
  }
  if (!fwref::host::write_atomic(argv[4], y.data(), y.size() * 4, &error)) return fail(error);
  return 0;
} catch (const std::exception& e) {
  return fwref::host::fail_exception("fwref_activations", e);
}
