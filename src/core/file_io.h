#pragma once
// Whole-file reads and crash-safe writes.
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace edrnr {

// Reads the whole file. Throws Error naming the path if it is missing or unreadable.
std::vector<uint8_t> read_file_bytes(const std::filesystem::path& path);
std::string read_file_text(const std::filesystem::path& path);

// Writes to "<path>.tmp.<pid>" and renames it over `path`, so a reader never
// sees a half-written file and an interrupted write loses nothing.
void write_file_atomic(const std::filesystem::path& path, std::string_view bytes);
void write_file_atomic(const std::filesystem::path& path, const std::vector<uint8_t>& bytes);

}  // namespace edrnr
