// tools/host_files.hpp -- scope: what the host programs check before they read or write a file:
// an output that is not a regular file (symlink, FIFO, device, folder) or that is one of the
// inputs is refused (fwref_infer --out once replaced a symlink, a FIFO and /dev/full by a regular
// file, and --out equal to --weights destroyed the weights with exit 0); and weights.bin is
// checked against the sha256 export/manifest.json records for it (--manifest), from the one read of it
// that is then parsed (load_weights).
#pragma once

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <string>
#include <utility>
#include <vector>

#include <sys/stat.h>

#include "host_common.hpp"

namespace fwref {
namespace host {

// ``out`` may be absent or a regular file that is none of ``inputs`` (paths, same order as
// ``what``); otherwise false and a one-line reason in ``error``.
inline bool output_allowed(const std::string& out, const std::vector<std::string>& inputs,
                           const std::vector<std::string>& what, std::string* error) {
  struct stat so {};
  if (::lstat(out.c_str(), &so) != 0) return true;  // absent: written fresh
  if (!S_ISREG(so.st_mode)) {
    const char* kind = S_ISLNK(so.st_mode) ? "a symlink" : S_ISDIR(so.st_mode) ? "a folder"
                     : S_ISFIFO(so.st_mode) ? "a FIFO" : "a device or special file";
    *error = "refusing to write --out " + out + ": it is " + kind + ", not a regular file";
    return false;
  }
  for (std::size_t i = 0; i < inputs.size(); ++i) {
    struct stat si {};
    if (!inputs[i].empty() && ::stat(inputs[i].c_str(), &si) == 0 && si.st_dev == so.st_dev &&
        si.st_ino == so.st_ino) {
      *error = "refusing to write --out " + out + ": it is the " + what[i] + " " + inputs[i];
      return false;
    }
  }
  return true;
}

// SHA-256 (FIPS 180-4) of ``data``, lower-case hex.
inline std::string sha256_hex(const std::vector<unsigned char>& data) {
  static const std::uint32_t k[64] = {
      0x428a2f98, 0x71374491, 0xb5c0fbcf, 0xe9b5dba5, 0x3956c25b, 0x59f111f1, 0x923f82a4, 0xab1c5ed5,
      0xd807aa98, 0x12835b01, 0x243185be, 0x550c7dc3, 0x72be5d74, 0x80deb1fe, 0x9bdc06a7, 0xc19bf174,
      0xe49b69c1, 0xefbe4786, 0x0fc19dc6, 0x240ca1cc, 0x2de92c6f, 0x4a7484aa, 0x5cb0a9dc, 0x76f988da,
      0x983e5152, 0xa831c66d, 0xb00327c8, 0xbf597fc7, 0xc6e00bf3, 0xd5a79147, 0x06ca6351, 0x14292967,
      0x27b70a85, 0x2e1b2138, 0x4d2c6dfc, 0x53380d13, 0x650a7354, 0x766a0abb, 0x81c2c92e, 0x92722c85,
      0xa2bfe8a1, 0xa81a664b, 0xc24b8b70, 0xc76c51a3, 0xd192e819, 0xd6990624, 0xf40e3585, 0x106aa070,
      0x19a4c116, 0x1e376c08, 0x2748774c, 0x34b0bcb5, 0x391c0cb3, 0x4ed8aa4a, 0x5b9cca4f, 0x682e6ff3,
      0x748f82ee, 0x78a5636f, 0x84c87814, 0x8cc70208, 0x90befffa, 0xa4506ceb, 0xbef9a3f7, 0xc67178f2};
  std::uint32_t h[8] = {0x6a09e667, 0xbb67ae85, 0x3c6ef372, 0xa54ff53a,
                        0x510e527f, 0x9b05688c, 0x1f83d9ab, 0x5be0cd19};
  std::vector<unsigned char> m(data);
  const std::uint64_t bits = std::uint64_t(data.size()) * 8;
  m.push_back(0x80);
  while (m.size() % 64 != 56) m.push_back(0);
  for (int i = 7; i >= 0; --i) m.push_back(static_cast<unsigned char>(bits >> (8 * i)));
  auto rotr = [](std::uint32_t x, int n) { return (x >> n) | (x << (32 - n)); };
  for (std::size_t off = 0; off < m.size(); off += 64) {
    std::uint32_t w[64];
    for (int i = 0; i < 16; ++i) {
      w[i] = std::uint32_t(m[off + 4 * i]) << 24 | std::uint32_t(m[off + 4 * i + 1]) << 16 |
             std::uint32_t(m[off + 4 * i + 2]) << 8 | std::uint32_t(m[off + 4 * i + 3]);
    }
    for (int i = 16; i < 64; ++i) {
      const std::uint32_t s0 = rotr(w[i - 15], 7) ^ rotr(w[i - 15], 18) ^ (w[i - 15] >> 3);
      const std::uint32_t s1 = rotr(w[i - 2], 17) ^ rotr(w[i - 2], 19) ^ (w[i - 2] >> 10);
      w[i] = w[i - 16] + s0 + w[i - 7] + s1;
    }
    std::uint32_t a = h[0], b = h[1], c = h[2], d = h[3], e = h[4], f = h[5], g = h[6], hh = h[7];
    for (int i = 0; i < 64; ++i) {
      const std::uint32_t t1 = hh + (rotr(e, 6) ^ rotr(e, 11) ^ rotr(e, 25)) + ((e & f) ^ (~e & g)) + k[i] + w[i];
      const std::uint32_t t2 = (rotr(a, 2) ^ rotr(a, 13) ^ rotr(a, 22)) + ((a & b) ^ (a & c) ^ (b & c));
      hh = g, g = f, f = e, e = d + t1, d = c, c = b, b = a, a = t1 + t2;
    }
    h[0] += a, h[1] += b, h[2] += c, h[3] += d, h[4] += e, h[5] += f, h[6] += g, h[7] += hh;
  }
  char hex[65];
  for (int i = 0; i < 8; ++i) std::snprintf(hex + 8 * i, 9, "%08x", h[i]);
  return std::string(hex, 64);
}

// The sha256 manifest.json records for ``name`` ("files": {"<name>": {"sha256": "<64 hex>", ...}});
// empty when the manifest does not list it. The manifest is quadfdi's own strict JSON, so a search
// for the key, then "sha256" inside the object that follows it, is enough (no JSON library on the host
// side). One pass: every search starts where the previous one ended.
inline std::string manifest_sha256(const std::string& manifest, const std::string& name) {
  const std::string key = "\"" + name + "\"", field = "\"sha256\"";
  const std::size_t n = manifest.size();
  auto blank = [&](std::size_t p) {
    while (p < n && (manifest[p] == ' ' || manifest[p] == '\n' || manifest[p] == '\t' || manifest[p] == '\r')) ++p;
    return p;
  };
  std::size_t from = 0, pos;
  while ((pos = manifest.find(key, from)) != std::string::npos) {
    std::size_t p = blank(pos + key.size());
    from = p;
    if (p >= n || manifest[p] != ':') continue;
    p = blank(p + 1);
    if (p >= n || manifest[p] != '{') continue;
    const std::size_t close = manifest.find('}', p);
    if (close == std::string::npos) return std::string();
    const auto s = std::search(manifest.begin() + p, manifest.begin() + close, field.begin(), field.end());
    from = close;
    if (s == manifest.begin() + close) continue;
    const std::size_t q = manifest.find('"', manifest.find(':', std::size_t(s - manifest.begin())) + 1);
    if (q != std::string::npos && q < close && q + 65 <= n) return manifest.substr(q + 1, 64);
  }
  return std::string();
}

// weights.bin at ``weights`` read once (a regular file of at most limits::kWeightsFileBytes) into ``wf``; with
// ``manifest`` (--manifest) its bytes must first have the sha256 the export's manifest records for weights.bin.
// False with a one-line reason in ``error``.
inline bool load_weights(const std::string& weights, const std::string& manifest, WeightsFile* wf,
                         std::string* error) {
  std::vector<unsigned char> text, wbytes;
  if (!manifest.empty() && !read_file(manifest, "manifest", limits::kManifestFileBytes, &text, error)) return false;
  if (read_regular_file(weights, "weights file", limits::kWeightsFileBytes, &wbytes, error,
                        " (run `quadfdi export` first)") != Status::kOk) {
    return false;
  }
  if (!manifest.empty()) {
    const std::string expected = manifest_sha256(std::string(text.begin(), text.end()), "weights.bin");
    if (expected.empty()) {
      *error = "manifest " + manifest + " has no sha256 for weights.bin (files.weights.bin.sha256)";
      return false;
    }
    const std::string found = sha256_hex(wbytes);
    if (found != expected) {
      *error = "weights " + weights + ": sha256 " + found.substr(0, 16) + "... differs from " +
               expected.substr(0, 16) + "... recorded in " + manifest + " (files.weights.bin.sha256)";
      return false;
    }
  }
  return wf->load_bytes(std::move(wbytes), weights, error) == Status::kOk;
}

}  // namespace host
}  // namespace fwref
