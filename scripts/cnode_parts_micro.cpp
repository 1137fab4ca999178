// scripts/cnode_parts_micro.cpp -- where the CNODE's steady-state time goes, fp32 against int8, part by part
// (docs/bench.md, "The CNODE field on an AVX2 host"): on a real weights.bin and real windows, each part of
// src/cnode.cpp's infer run over all the windows in turn (the workspace warm, its one-time int16 / column-major
// weight copies made before timing), the loop timed with std::chrono::steady_clock; 15 rounds, the parts
// interleaved within a round, medians in ns per window. The parts call cnode.cpp's own functions: this file
// includes src/cnode.cpp (measurement only), so it times the code that ships, not a copy of it.
//
//   g++ -O3 -DNDEBUG -std=c++17 -march=native -ffp-contract=off -fno-trapping-math -DFWREF_CNODE_W_INT16
//       -DFWREF_CNODE_U_INT16 -DEIGEN_RUNTIME_NO_MALLOC -Ifirmware_ref/include -Ifirmware_ref/src
//       -I/usr/include/eigen3 scripts/cnode_parts_micro.cpp $(ls firmware_ref/src/*.cpp | grep -v cnode.cpp)
//       -o /tmp/cnode_parts_micro
//   taskset -c 1 /tmp/cnode_parts_micro weights.bin windows.f32     (windows: (n, W, C) float32, raw)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <fstream>
#include <memory>
#include <string>
#include <vector>

#include "../firmware_ref/src/cnode.cpp"
#include "fwref/weights_file.hpp"

namespace {

using Clock = std::chrono::steady_clock;

struct Part {
  const char* name;
  std::vector<double> ns;  // per round: ns per window
};

template <class F>
double per_window_ns(int n, F f) {
  const auto a = Clock::now();
  for (int i = 0; i < n; ++i) f(i);
  return std::chrono::duration<double, std::nano>(Clock::now() - a).count() / n;
}

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

}  // namespace

int main(int argc, char** argv) {
  using namespace fwref;
  if (argc != 3) return std::fprintf(stderr, "usage: cnode_parts_micro weights.bin windows.f32\n"), 2;
  WeightsFile wf;
  std::string err;
  CnodeF32 mf;
  CnodeI8 mq;
  if (wf.load(argv[1], &err) != Status::kOk || wf.bind(&mf, &err) != Status::kOk || wf.bind(&mq, &err) != Status::kOk) {
    return std::fprintf(stderr, "cnode_parts_micro: %s\n", err.c_str()), 2;
  }
  const CnodeDims& d = mq.dims;
  const int WC = d.window * d.channels, H = d.hidden, L = d.latent, S = d.stage_times;
  (void)S;
  std::ifstream in(argv[2], std::ios::binary);
  std::vector<float> xs((std::istreambuf_iterator<char>(in)), {});  // bytes, resized below
  in.clear(), in.seekg(0, std::ios::end);
  const long bytes = static_cast<long>(in.tellg());
  const int n = static_cast<int>(bytes / (4L * WC));
  xs.assign(static_cast<std::size_t>(n) * WC, 0.0f);
  in.seekg(0), in.read(reinterpret_cast<char*>(xs.data()), n * 4L * WC);
  if (n < 1) return std::fprintf(stderr, "cnode_parts_micro: no whole window in %s\n", argv[2]), 2;
  auto wsf = std::make_unique<CnodeWorkspace>();
  auto wsq = std::make_unique<CnodeWorkspace>();
  std::vector<float> out(static_cast<std::size_t>(n) * d.classes);
  infer(mf, xs.data(), out.data(), *wsf), infer(mq, xs.data(), out.data(), *wsq);  // one-time copies
  const float* X = xs.data();
  CnodeWorkspace& f = *wsf;
  CnodeWorkspace& q = *wsq;
  std::int32_t acc[kMaxChannels];
  const detail::StageWeights16 w16 = detail::int16_copies(mq, q);
  float lin2_mult[kMaxLatent];
  for (int o = 0; o < L; ++o) lin2_mult[o] = mq.s_hidden * mq.lin2_w.scale[o];
  const detail::Field16 one_call = detail::field16(mq, w16.lin1z, w16.lin2, lin2_mult);
  // Per window, infer's steps in infer's order, a time stamp after each (the window's first read, by the input
  // check, is the one from L3, as in the bench's fwref_infer); ns per window summed over the windows.
  std::vector<Part> parts = {{"fp32 infer (whole)", {}}, {"int8 infer (whole)", {}}, {"fp32 input check", {}},
                             {"fp32 control path", {}},  {"fp32 RK4 (4N fields)", {}}, {"fp32 head", {}},
                             {"int8 input check", {}},   {"int8 control rows", {}},   {"int8 encoder + tanh", {}},
                             {"int8 lin1_u rows", {}},   {"int8 RK4 (4N fields)", {}}, {"int8 head", {}}};
  auto field_q = [&](int e, const CnodeWorkspace::Lat& z, CnodeWorkspace::Lat& k) {
    k.resize(L);
    one_call(z.data(), mq.s_stage[e], q.v + mq.stage_index[e] * H, k.data());
  };
#if defined(FWREF_HAS_F32_AVX512)
  const detail::F32Copies tc = detail::f32_copies(mf, f);
  auto field_f = [&](int e, const CnodeWorkspace::Lat& z, CnodeWorkspace::Lat& k) {
    detail::field_t(mf, tc, f.v + mf.stage_index[e] * H, z, f.a, k);
  };
#endif
  for (int r = 0; r < 15; ++r) {
    parts[0].ns.push_back(per_window_ns(n, [&](int i) { infer(mf, X + long(i) * WC, &out[i * d.classes], f); }));
    parts[1].ns.push_back(per_window_ns(n, [&](int i) { infer(mq, X + long(i) * WC, &out[i * d.classes], q); }));
    std::vector<double> t(parts.size(), 0.0);
    for (int i = 0; i < n; ++i) {
      const float* x = X + long(i) * WC;
      Clock::time_point c[7];
      c[0] = Clock::now();
      out[0] = all_finite_n(x, WC);
      c[1] = Clock::now();
#if defined(FWREF_HAS_F32_AVX512)  // infer's control path (fp32): on avx2field the registers / padded copies one
      if (!detail::control_path_avx2(mf, tc, x, f, nullptr)) control_path_f32(mf, x, tc.lin1u, f, nullptr);
#else
      control_path_f32(mf, x, nullptr, f, nullptr);
#endif
      c[2] = Clock::now();
#if defined(FWREF_HAS_F32_AVX512)
      detail::rk4_integrate(mf.rk4, d.steps, f.z, f.k1, f.k2, f.k3, f.k4, f.state, field_f, nullptr);
#endif
      c[3] = Clock::now();
      MapVec o(&out[i * d.classes], d.classes);
      matvec_bias_f32(mf.head_w, f.z, mf.head_b, o);
      c[4] = Clock::now();
      for (int j = 0; j < 3; ++j) t[2 + j] += std::chrono::duration<double, std::nano>(c[j + 1] - c[j]).count();
      t[5] += std::chrono::duration<double, std::nano>(c[4] - c[3]).count();
    }
    for (int i = 0; i < n; ++i) {
      const float* x = X + long(i) * WC;
      Clock::time_point c[7];
      c[0] = Clock::now();
      out[0] = all_finite_n(x, WC);
      c[1] = Clock::now();
      detail::quantize_stage_controls(mq, x, acc, q, nullptr);
      c[2] = Clock::now();
      q.z.resize(L);
#if defined(FWREF_HAS_LINEAR_W16_AVX2)  // control_path_i8's encoder step
      if (!linear_folded_w16_avx2(w16.enc, L, d.channels, q.uq, 1, mq.encoder_w.scale, mq.encoder_b, q.z.data()))
#endif
        linear_i8_folded(mq.encoder_w.q, mq.encoder_w.scale, L, d.channels, q.uq, mq.encoder_b, q.z.data());
      tanh_inplace(q.z);
      c[3] = Clock::now();
      lin1_u_rows(mq, w16.lin1u, q);
      c[4] = Clock::now();
      detail::rk4_integrate(mq.rk4, d.steps, q.z, q.k1, q.k2, q.k3, q.k4, q.state, field_q, nullptr);
      c[5] = Clock::now();
      quantize_all(q.z.data(), L, mq.s_z1, q.q_lat);
      linear_i8_tensor(mq.head_w.q, mq.head_w.scale, d.classes, L, q.q_lat, mq.s_z1, mq.head_b, &out[i * d.classes]);
      c[6] = Clock::now();
      for (int j = 0; j < 6; ++j) t[6 + j] += std::chrono::duration<double, std::nano>(c[j + 1] - c[j]).count();
    }
    for (std::size_t j = 2; j < parts.size(); ++j) parts[j].ns.push_back(t[j] / n);
  }
  std::printf("%d windows, S = %d, H = %d, L = %d, 15 rounds; median ns per window (min .. max of rounds)\n", n, S, H, L);
  for (const Part& p : parts) {
    if (p.ns.empty()) continue;
    std::printf("%-22s %8.0f  (%.0f .. %.0f)\n", p.name, median(p.ns), *std::min_element(p.ns.begin(), p.ns.end()),
                *std::max_element(p.ns.begin(), p.ns.end()));
  }
  return 0;
}
