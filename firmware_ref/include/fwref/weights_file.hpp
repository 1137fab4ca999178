// fwref/weights_file.hpp -- scope: weights.bin on the host: read and check the file
// (fwref/container.hpp), then bind one section to a model struct (fwref/cnode.hpp, fwref/gru.hpp)
// after checking that every tensor the model needs is present with the dtype, shape and scales its
// section's dimensions imply, and that the dimensions fit this build's compile-time maxima. Which
// tensors, with which shapes, is the generated table fwref/weights_layout_gen.hpp. The
// values are copied once into typed storage owned by the WeightsFile (no aliasing or alignment
// assumptions about the file's bytes); the bound model points into it.
#pragma once

#include <cstdint>
#include <deque>
#include <string>
#include <vector>

#include "fwref/cnode.hpp"
#include "fwref/container.hpp"
#include "fwref/gru.hpp"
#include "fwref/status.hpp"

namespace fwref {

class WeightsFile {
 public:
  // A regular file of at most limits::kWeightsFileBytes (fwref/read_limits.hpp).
  Status load(const std::string& path, std::string* error);
  // ``bytes`` read already (its sha256 checked against a manifest, or a fuzzer's input); ``path`` names it.
  Status load_bytes(std::vector<unsigned char> bytes, const std::string& path, std::string* error);

  // Bind the section (model, precision); kMissingSection if the file does not hold it.
  Status bind(CnodeF32* out, std::string* error);
  Status bind(CnodeI8* out, std::string* error);
  Status bind(GruF32* out, std::string* error);
  Status bind(GruI8* out, std::string* error);
  // The optional motor-head sections (fwref/motor.hpp): kMissingSection for a model without the head.
  Status bind(CnodeMotorF32* out, std::string* error);
  Status bind(CnodeMotorI8* out, std::string* error);
  Status bind(GruMotorF32* out, std::string* error);
  Status bind(GruMotorI8* out, std::string* error);
  // The streaming GRU's sections (model code kModelSgru, the GRU's tensors with window 1:
  // fwref/gru_step.hpp), in its own file export/sgru_weights.bin; kMissingSection in weights.bin.
  Status bind_sgru(GruF32* out, std::string* error);
  Status bind_sgru(GruI8* out, std::string* error);

  const Container& container() const { return file_; }

 private:
  friend class Binder;
  template <class Model>
  Status bind_section(Model* out, std::string* error);
  template <class Model>
  Status bind_as(Model* out, std::uint32_t model, const char* label, std::string* error);
  Container file_;
  std::deque<std::vector<float>> f32_;
  std::deque<std::vector<std::int8_t>> i8_;
  std::deque<std::vector<std::int32_t>> i32_;
};

}  // namespace fwref
