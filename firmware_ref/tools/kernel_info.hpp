// tools/kernel_info.hpp -- scope: the lines that say which int8 kernel runs and what the CPU and the
// fp32 build support (fwref_kernels --info, fwref_parity --kernel-info; bench records them):
//   cpu_flags: sse4.2=1 avx=1 avx2=1 fma=1 avx512f=0 avx512vl=0 avx512vnni=0
//   fp32_build: x86-64 sse4.2 avx avx2 fma
//   fp32_kernel: fma-avx2-8row                  (fma-avx512-16row on an AVX-512F CPU)
//   fp32_cnode_field: avx2-one-call             (avx512-one-call on AVX-512F; separate: FWREF_F32_KERNEL=avx2)
//   int8_kernel: avx2field
//   int8_kernels: portable=runs avx2=runs avx2field=runs avx512vnni=no
//   gru_int8_products: w16-vpmaddwd             (x86-64 only: w8-vpdpbusd with avx512vnni)
//   cnode_int8_products: w16-vpmaddwd-field     (x86-64 only: the same choice for the CNODE's products;
//                                                -field: its vector field in one call, avx2field)
#pragma once

#include <cstdio>

#include <cstring>

#include "fwref/field_f32_avx2.hpp"
#include "fwref/field_w16_avx2.hpp"
#include "fwref/kernels_i8.hpp"
#include "fwref/kernels_w8_vnni.hpp"
#include "fwref/vmath_f32.hpp"

namespace fwref {
namespace host {

inline void print_kernel_info(std::FILE* out) {
#if defined(__x86_64__)
  __builtin_cpu_init();
  std::fprintf(out, "cpu_flags: sse4.2=%d avx=%d avx2=%d fma=%d avx512f=%d avx512vl=%d avx512vnni=%d\n",
               __builtin_cpu_supports("sse4.2") ? 1 : 0, __builtin_cpu_supports("avx") ? 1 : 0,
               __builtin_cpu_supports("avx2") ? 1 : 0, __builtin_cpu_supports("fma") ? 1 : 0,
               __builtin_cpu_supports("avx512f") ? 1 : 0, __builtin_cpu_supports("avx512vl") ? 1 : 0,
               __builtin_cpu_supports("avx512vnni") ? 1 : 0);
#else
  std::fprintf(out, "cpu_flags: (not x86-64)\n");
#endif
#if defined(__x86_64__) && !defined(FWREF_PORTABLE_KERNELS)
  std::fprintf(out, "fp32_build: %s\n", fp32_build_isa());
  // the fp32 products' kernel, chosen at run time (fwref/kernels_f32_avx512.hpp; FWREF_F32_KERNEL=avx2)
  std::fprintf(out, "fp32_kernel: %s\n", matvec_f32_kernel_name());
  // the fp32 CNODE's vector field: in one call on AVX-512F or on AVX2 (fwref/field_f32_avx2.hpp), else the
  // separate products of fp32_kernel
  const char* f32_field = "separate";
#if defined(FWREF_HAS_F32_AVX512)
  if (gemv_f32_avx512_active()) f32_field = "avx512-one-call";
#endif
#if defined(FWREF_HAS_F32_FIELD_AVX2)
  if (field_f32_avx2_active()) f32_field = "avx2-one-call";
#endif
  std::fprintf(out, "fp32_cnode_field: %s\n", f32_field);
  std::fprintf(out, "int8_kernel: %s\n", gemv_i8_kernel_name());
  const GemvI8Kernel* ks = nullptr;
  const int n = gemv_i8_kernels(&ks);
  std::fprintf(out, "int8_kernels:");
  for (int k = 0; k < n; ++k) std::fprintf(out, " %s=%s", ks[k].name, ks[k].cpu_runs ? "runs" : "no");
  std::fprintf(out, "\n");
  // which packed copy the host GRU's and CNODE's int8 products run on (src/gru.cpp, src/cnode.cpp and
  // src/cnode_w8.cpp, fwref/kernels_w8_vnni.hpp): one run-time choice for both models
  const bool portable = std::strcmp(gemv_i8_kernel_name(), "portable") == 0;
  const char* products = gemv_w8_kernel() != nullptr ? "w8-vpdpbusd" : portable ? "portable" : "w16-vpmaddwd";
  bool field = false;  // the CNODE's field in one call on the int16 copies (fwref/field_w16_avx2.hpp)
#if defined(FWREF_HAS_FIELD_W16_AVX2)
  field = field_w16_avx2_active();
#endif
  std::fprintf(out, "gru_int8_products: %s\ncnode_int8_products: %s%s\n", products, products, field ? "-field" : "");
#else
  std::fprintf(out, "fp32_build: generic\nint8_kernel: %s\nint8_kernels: %s=runs\n", gemv_i8_kernel_name(),
               gemv_i8_kernel_name());
#endif
}

}  // namespace host
}  // namespace fwref
