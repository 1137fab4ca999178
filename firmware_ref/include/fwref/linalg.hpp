// fwref/linalg.hpp -- scope: the storage types of the models: non-owning views of the weight
// matrices (which live in weights.bin's buffer on the host, in flash on the microcontroller) and
// the fixed-capacity Eigen vectors of the state. Eigen::Matrix<float, Dynamic, 1, 0, Max, 1> keeps
// its Max coefficients inline (no heap: its size is set from weights.bin, checked against Max).
#pragma once

#include <cstdint>

#include <Eigen/Core>

namespace fwref {

// A float32 matrix in PyTorch's (out, in) row-major layout: y = W x.
struct MatF {
  const float* data;
  int rows;
  int cols;
};

// An int8 matrix, (out, in) row-major, symmetric, zero point 0, one float32 scale per row.
struct MatQ {
  const std::int8_t* q;
  const float* scale;  // (rows,)
  int rows;
  int cols;
};

template <int Max>
using VecN = Eigen::Matrix<float, Eigen::Dynamic, 1, Eigen::ColMajor, Max, 1>;

using ConstMapMat = Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, Eigen::Dynamic, Eigen::RowMajor>>;
using MapVec = Eigen::Map<Eigen::Matrix<float, Eigen::Dynamic, 1>>;
using ConstMapVec = Eigen::Map<const Eigen::Matrix<float, Eigen::Dynamic, 1>>;

inline ConstMapMat map(const MatF& m) { return ConstMapMat(m.data, m.rows, m.cols); }

// y = W x, one dot product per output row (Eigen's coefficient-based lazyProduct): unlike the GEMV
// kernel of operator*, it needs no temporary that Eigen could put on the heap (the Cortex-M build
// links no malloc at all), and each row is still a vectorised reduction on the host.
template <class Dst, class Src>
inline void matvec(const MatF& w, const Src& x, Dst&& y) {
  y.noalias() = map(w).lazyProduct(x);
}

}  // namespace fwref
