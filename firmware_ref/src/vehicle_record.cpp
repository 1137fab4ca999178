// src/vehicle_record.cpp -- scope: fwref/vehicle_record.hpp's host loader of a vehicle record file
// (formats/vehicle_record_bin.py): the bounded open of fwref/file_read.hpp, a size check (116 bytes, 112 for
// a version 1 record), the bytes into a fixed buffer, the parse. Every failure is one line naming the file.
#include "fwref/vehicle_record.hpp"

#include "fwref/file_read.hpp"
#include "fwref/read_limits.hpp"

namespace fwref {

Status load_vehicle_record(const std::string& path, Profile expect, VehicleRecord* out, std::string* error) {
  RegularFile f;
  Status s = f.open(path, "vehicle record", limits::kVehicleRecordFileBytes, error,
                    " (write one: quadfdi vehicle record VEHICLE.json --out RECORD.bin)");
  if (s != Status::kOk) return s;
  if (f.size() != std::uint64_t(vehicle::kFileBytes) && f.size() != std::uint64_t(vehicle::kFileBytesV1)) {
    *error = f.where() + " holds " + std::to_string(f.size()) + " bytes, a vehicle record " +
             std::to_string(vehicle::kFileBytes) + " (" + std::to_string(vehicle::kFileBytesV1) +
             " for version 1; truncated or not a vehicle record)";
    return Status::kBadSize;
  }
  unsigned char bytes[vehicle::kFileBytes];
  if ((s = f.read_all(bytes, error)) != Status::kOk) return s;
  const char* why = "";
  s = parse_vehicle_record(bytes, static_cast<std::size_t>(f.size()), expect, out, &why);
  if (s == Status::kDimsInvalid) {
    std::uint32_t id = 0;
    std::memcpy(&id, bytes + 12, 4);
    const std::string name = id < std::uint32_t(kProfileCount) ? profile_tables::kSpecs[id].name : "id " + std::to_string(id);
    *error = f.where() + " is for profile '" + name + "', the model's is '" +
             profile_tables::kSpecs[static_cast<int>(expect)].name + "'";
  } else if (s != Status::kOk) {
    *error = f.where() + " " + why;
  }
  return s;
}

}  // namespace fwref
