// Helpers shared by the fuzz targets.
#pragma once
#include <spdlog/spdlog.h>
#include <unistd.h>

#include <cstdint>
#include <fstream>
#include <string>

namespace mbsdf::fuzz {

inline void quietLogs() {
  spdlog::set_level(spdlog::level::off);
}

// Writes the input to a per-process temporary file with the given extension.
inline std::string writeTemp(const uint8_t* data, size_t size, const char* ext) {
  std::string path = "/tmp/microbsdf-fuzz-" + std::to_string(getpid()) + ext;
  std::ofstream f(path, std::ios::binary | std::ios::trunc);
  f.write(reinterpret_cast<const char*>(data), std::streamsize(size));
  return path;
}

}  // namespace mbsdf::fuzz
