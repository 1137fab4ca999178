// src/container.cpp -- scope: parsing and checking the weights.bin / reference.bin container
// (fwref/container.hpp). Error texts follow formats/binfmt.py's so that Python and C++ say the
// same thing about the same broken file.
#include "fwref/container.hpp"

#include <cstdarg>
#include <cstdio>
#include <cstring>
#include <utility>

#include "fwref/file_read.hpp"

namespace fwref {

namespace {

constexpr std::size_t kFileHeader = 24;     // magic[8], u32 version, u32 n_sections, u64 file_size
constexpr std::size_t kSectionHeader = 52;  // "SECT", u32 size, u32 model, u32 precision, u32 dims[8], u32 n
constexpr std::size_t kTensorHeader = 84;   // name[48], dtype, ndim, shape[4], axis, n_scales, data_bytes
constexpr std::size_t kNameBytes = 48;
const char* const kRegen = " (re-run `quadfdi export`)";

std::uint32_t u32_at(const unsigned char* p) {
  return std::uint32_t(p[0]) | (std::uint32_t(p[1]) << 8) | (std::uint32_t(p[2]) << 16) | (std::uint32_t(p[3]) << 24);
}

std::uint64_t u64_at(const unsigned char* p) { return std::uint64_t(u32_at(p)) | (std::uint64_t(u32_at(p + 4)) << 32); }

// A magic as Python prints bytes: b'QFDIWTS\x00'.
std::string bytes_repr(const unsigned char* p, std::size_t n) {
  std::string out = "b'";
  for (std::size_t i = 0; i < n; ++i) {
    const unsigned char c = p[i];
    if (c >= 32 && c < 127 && c != '\'' && c != '\\') {
      out += static_cast<char>(c);
    } else {
      out += fmt("\\x%02x", c);
    }
  }
  return out + "'";
}

std::size_t dtype_size(std::uint32_t code) { return code == 2 ? 1 : 4; }

}  // namespace

std::string fmt(const char* f, ...) {
  char buf[512];
  va_list ap;
  va_start(ap, f);
  std::vsnprintf(buf, sizeof buf, f, ap);
  va_end(ap);
  return buf;
}

const char* dtype_name(DType t) {
  switch (t) {
    case DType::kF32: return "float32";
    case DType::kI8: return "int8";
    case DType::kI32: return "int32";
  }
  return "?";
}

const char* model_name(std::uint32_t model) {
  const char* name = model_code_name(model);
  return name != nullptr ? name : "?";
}

const char* precision_name(std::uint32_t precision) {
  const char* name = precision_code_name(precision);
  return name != nullptr ? name : "?";
}

std::string TensorInfo::shape_text() const {
  std::string s = "(";
  for (int i = 0; i < ndim; ++i) s += (i ? ", " : "") + std::to_string(shape[i]);
  return s + (ndim == 1 ? ",)" : ")");
}

const TensorInfo* SectionInfo::find(const std::string& name) const {
  for (const TensorInfo& t : tensors) {
    if (t.name == name) return &t;
  }
  return nullptr;
}

std::string SectionInfo::label() const { return std::string(model_name(model)) + " " + precision_name(precision); }

std::uint32_t crc32(const unsigned char* data, std::size_t n, std::uint32_t crc) {
  struct Table {
    std::uint32_t v[256];
    Table() {
      for (std::uint32_t i = 0; i < 256; ++i) {
        std::uint32_t c = i;
        for (int k = 0; k < 8; ++k) c = (c & 1U) ? 0xEDB88320U ^ (c >> 1) : c >> 1;
        v[i] = c;
      }
    }
  };
  static const Table table;  // built once, thread-safe (C++11 static initialisation)
  crc = ~crc;
  for (std::size_t i = 0; i < n; ++i) crc = table.v[(crc ^ data[i]) & 0xFFU] ^ (crc >> 8);
  return ~crc;
}

Status Container::load(const std::string& path, const char* magic, std::uint32_t version, const char* what,
                       std::uint64_t max_bytes, std::string* error) {
  std::vector<unsigned char> bytes;
  sections_.clear();
  bytes_.clear();
  where_ = std::string(what) + " " + path;
  const Status s = read_regular_file(path, what, max_bytes, &bytes, error, " (run `quadfdi export` first)");
  if (s != Status::kOk) return s;
  return parse_bytes(std::move(bytes), path, magic, version, what, error);
}

Status Container::parse_bytes(std::vector<unsigned char> bytes, const std::string& path, const char* magic,
                              std::uint32_t version, const char* what, std::string* error) {
  where_ = std::string(what) + " " + path;
  bytes_ = std::move(bytes);
  sections_.clear();
  return parse(magic, version, what, error);
}

Status Container::parse(const char* magic, std::uint32_t version, const char* what, std::string* error) {
  const unsigned char* b = bytes_.data();
  const std::size_t n = bytes_.size();
  const std::size_t magic_n = n < 8 ? n : 8;
  if (n < kFileHeader && (n == 0 || std::memcmp(b, magic, magic_n) == 0)) {
    *error = fmt("%s is truncated: %zu bytes, shorter than its %zu-byte header%s", where_.c_str(), n, kFileHeader, kRegen);
    return Status::kTruncated;
  }
  if (n < 8 || std::memcmp(b, magic, 8) != 0) {
    *error = fmt("%s is not a quadfdi %s (magic %s, expected %s)", where_.c_str(), what,
                 bytes_repr(b, magic_n).c_str(), bytes_repr(reinterpret_cast<const unsigned char*>(magic), 8).c_str());
    return Status::kBadMagic;
  }
  if (n < kFileHeader) {
    *error = fmt("%s is truncated: %zu bytes, shorter than its %zu-byte header%s", where_.c_str(), n, kFileHeader, kRegen);
    return Status::kTruncated;
  }
  const std::uint32_t ver = u32_at(b + 8), n_sections = u32_at(b + 12);
  const std::uint64_t size = u64_at(b + 16);
  if (ver != version) {
    *error = fmt("%s has format version %u, this reader reads version %u%s", where_.c_str(), ver, version, kRegen);
    return Status::kBadVersion;
  }
  if (size != n) {
    *error = fmt("%s is truncated (or has trailing bytes): its header says %llu bytes, the file has %zu%s",
                 where_.c_str(), static_cast<unsigned long long>(size), n, kRegen);
    return Status::kTruncated;
  }
  if (n < kFileHeader + 4) {
    *error = fmt("%s is truncated: %zu bytes leave no room for its CRC%s", where_.c_str(), n, kRegen);
    return Status::kTruncated;
  }
  if (crc32(b, n - 4) != u32_at(b + n - 4)) {
    *error = fmt("%s fails its file CRC-32 check: the file is corrupted%s", where_.c_str(), kRegen);
    return Status::kBadCrc;
  }
  // Each section takes at least its header and CRC: a count above that is a corrupted header.
  if (n_sections > (n - kFileHeader - 4) / (kSectionHeader + 4)) {
    *error = fmt("%s claims %u sections, its %zu bytes hold at most %zu", where_.c_str(), n_sections, n,
                 (n - kFileHeader - 4) / (kSectionHeader + 4));
    return Status::kBadHeader;
  }
  std::size_t pos = kFileHeader;
  const std::size_t end = n - 4;
  for (std::uint32_t i = 0; i < n_sections; ++i) {
    Status s = parse_section(pos, end, static_cast<int>(i), error);
    if (s != Status::kOk) return s;
  }
  if (pos != end) {
    *error = fmt("%s has %zu unexpected bytes after its %u sections", where_.c_str(), end - pos, n_sections);
    return Status::kBadSize;
  }
  return Status::kOk;
}

Status Container::parse_section(std::size_t& pos, std::size_t end, int index, std::string* error) {
  const unsigned char* b = bytes_.data();
  const std::size_t start = pos;
  if (end - pos < kSectionHeader) {
    *error = fmt("%s is truncated or corrupted: section %d header needs %zu bytes at offset %zu, only %zu left%s",
                 where_.c_str(), index, kSectionHeader, pos, end - pos, kRegen);
    return Status::kTruncated;
  }
  const unsigned char* h = b + pos;
  const std::uint32_t size = u32_at(h + 4), model = u32_at(h + 8), prec = u32_at(h + 12);
  if (std::memcmp(h, "SECT", 4) != 0 || model_code_name(model) == nullptr || precision_code_name(prec) == nullptr) {
    *error = fmt("%s: section %d has a bad header (tag %s, model %u, precision %u)", where_.c_str(), index,
                 bytes_repr(h, 4).c_str(), model, prec);
    return Status::kBadHeader;
  }
  if (size < kSectionHeader + 4 || size > end - start) {
    *error = fmt("%s: section %d claims %u bytes, %zu are left", where_.c_str(), index, size, end - start);
    return Status::kBadSize;
  }
  if (crc32(b + start, size - 4) != u32_at(b + start + size - 4)) {
    *error = fmt("%s: section %d (%s %s) fails its CRC-32 check", where_.c_str(), index, model_name(model),
                 precision_name(prec));
    return Status::kBadCrc;
  }
  SectionInfo sec;
  sec.model = model;
  sec.precision = prec;
  for (int i = 0; i < 8; ++i) sec.dims[i] = u32_at(h + 16 + 4 * i);
  const std::uint32_t n_tensors = u32_at(h + 48);
  const std::size_t inner_end = start + size - 4;
  if (n_tensors > (inner_end - start - kSectionHeader) / kTensorHeader) {
    *error = fmt("%s: section %d claims %u tensors, its %u bytes hold at most %zu", where_.c_str(), index, n_tensors,
                 size, (inner_end - start - kSectionHeader) / kTensorHeader);
    return Status::kBadHeader;
  }
  std::size_t p = start + kSectionHeader;
  for (std::uint32_t k = 0; k < n_tensors; ++k) {
    TensorInfo t;
    Status s = parse_tensor(p, inner_end, fmt("section %d tensor %u", index, k), &t, error);
    if (s != Status::kOk) return s;
    sec.tensors.push_back(t);
  }
  if (p != inner_end) {
    *error = fmt("%s: section %d has %zu bytes beyond its %u tensors", where_.c_str(), index, inner_end - p, n_tensors);
    return Status::kBadSize;
  }
  sections_.push_back(sec);
  pos = start + size;
  return Status::kOk;
}

Status Container::parse_tensor(std::size_t& pos, std::size_t end, const std::string& what, TensorInfo* t,
                               std::string* error) {
  const unsigned char* b = bytes_.data();
  auto take = [&](std::size_t n, const std::string& part) -> bool {
    if (n > end - pos) {
      *error = fmt("%s is truncated or corrupted: %s needs %zu bytes at offset %zu, only %zu left%s", where_.c_str(),
                   part.c_str(), n, pos, end - pos, kRegen);
      return false;
    }
    pos += n;
    return true;
  };
  const std::size_t head = pos;
  if (!take(kTensorHeader, what + " header")) return Status::kTruncated;
  const unsigned char* h = b + head;
  std::size_t name_len = 0;
  while (name_len < kNameBytes && h[name_len] != 0) ++name_len;
  t->name.assign(reinterpret_cast<const char*>(h), name_len);
  for (char& c : t->name) {
    if (static_cast<unsigned char>(c) < 32 || static_cast<unsigned char>(c) > 126) c = '?';
  }
  const std::uint32_t code = u32_at(h + 48), ndim = u32_at(h + 52);
  const std::int32_t axis = static_cast<std::int32_t>(u32_at(h + 72));
  const std::uint32_t n_scales = u32_at(h + 76), nbytes = u32_at(h + 80);
  // A writer sets unused shape entries to 0 and the axis of an unquantized tensor to -1; any other
  // value there is a corrupted header, refused like the rest.
  bool unused_zero = ndim <= 4;
  for (std::uint32_t i = ndim; i < 4 && unused_zero; ++i) unused_zero = u32_at(h + 56 + 4 * i) == 0;
  if (code < 1 || code > 3 || ndim > 4 || (axis != -1 && axis != 0) || (code != 2 && axis != -1) || !unused_zero) {
    *error = fmt("%s: %s ('%s') has a bad header (dtype %u, ndim %u, axis %d%s)", where_.c_str(), what.c_str(),
                 t->name.c_str(), code, ndim, axis, unused_zero ? "" : ", unused shape entries not 0");
    return Status::kBadHeader;
  }
  t->dtype = static_cast<DType>(code);
  t->ndim = static_cast<int>(ndim);
  t->axis = axis;
  std::uint64_t count = 1;
  for (int i = 0; i < 4; ++i) {
    const std::uint32_t d = u32_at(h + 56 + 4 * i);
    t->shape[i] = i < t->ndim ? static_cast<int>(d > 0x7FFFFFFFU ? 0x7FFFFFFFU : d) : 0;
    if (i < t->ndim) count *= d;
    if (count > (std::uint64_t(1) << 40)) count = std::uint64_t(1) << 40;  // clamp: no overflow below
  }
  t->count = static_cast<std::size_t>(count);
  const std::uint64_t want_bytes = count * dtype_size(code);
  if (nbytes != want_bytes) {
    *error = fmt("%s: %s ('%s') says %u data bytes, shape %s of %s needs %llu", where_.c_str(), what.c_str(),
                 t->name.c_str(), nbytes, t->shape_text().c_str(), dtype_name(t->dtype),
                 static_cast<unsigned long long>(want_bytes));
    return Status::kBadSize;
  }
  const long want_scales = code != 2 ? 0 : (axis == -1 ? 1 : (t->ndim ? t->shape[0] : -1));
  if (static_cast<long>(n_scales) != want_scales) {
    *error = fmt("%s: %s ('%s') has %u scales, expected %ld", where_.c_str(), what.c_str(), t->name.c_str(), n_scales,
                 want_scales);
    return Status::kBadSize;
  }
  t->n_scales = static_cast<int>(n_scales);
  t->data_offset = pos;
  if (!take(nbytes, what + " ('" + t->name + "') data")) return Status::kTruncated;
  if (!take((4 - nbytes % 4) % 4, what + " padding")) return Status::kTruncated;
  t->scales_offset = pos;
  if (!take(4 * std::size_t(n_scales), what + " scales")) return Status::kTruncated;
  if (!take(4 * std::size_t(n_scales), what + " zero points")) return Status::kTruncated;
  return Status::kOk;
}

const SectionInfo* Container::find(std::uint32_t model, std::uint32_t precision) const {
  for (const SectionInfo& s : sections_) {
    if (s.model == model && s.precision == precision) return &s;
  }
  return nullptr;
}

void Container::copy_f32(const TensorInfo& t, float* out) const {
  const unsigned char* p = bytes_.data() + t.data_offset;
  for (std::size_t i = 0; i < t.count; ++i) {
    const std::uint32_t v = u32_at(p + 4 * i);
    std::memcpy(out + i, &v, 4);
  }
}

void Container::copy_i8(const TensorInfo& t, std::int8_t* out) const {
  std::memcpy(out, bytes_.data() + t.data_offset, t.count);
}

void Container::copy_i32(const TensorInfo& t, std::int32_t* out) const {
  const unsigned char* p = bytes_.data() + t.data_offset;
  for (std::size_t i = 0; i < t.count; ++i) out[i] = static_cast<std::int32_t>(u32_at(p + 4 * i));
}

void Container::copy_scales(const TensorInfo& t, float* out) const {
  const unsigned char* p = bytes_.data() + t.scales_offset;
  for (int i = 0; i < t.n_scales; ++i) {
    const std::uint32_t v = u32_at(p + 4 * i);
    std::memcpy(out + i, &v, 4);
  }
}

std::int32_t Container::zero_point(const TensorInfo& t, int i) const {
  return static_cast<std::int32_t>(u32_at(bytes_.data() + t.scales_offset + 4 * std::size_t(t.n_scales) + 4 * i));
}

}  // namespace fwref
