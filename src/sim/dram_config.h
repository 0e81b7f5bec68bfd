#pragma once
// DDR3 system description: organisation, timing, currents and controller
// settings, loaded from a preset YAML file in configs/dram/ (see docs/dram.md).
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace edrnr::sim {

// Fields of a DRAM address, for the address mapping.
enum class AddressField : uint8_t { kChannel, kRank, kBank, kRow, kColumn };

struct DramConfig {
  std::string name;    // e.g. "DDR3-1600 4Gb x16, 64-bit bus"
  std::string source;  // where the values come from

  // Organisation. A rank is bus_width_bits / device_width_bits devices that
  // work in lock step; every count must be a power of two.
  uint32_t channels = 1;
  uint32_t ranks = 1;    // ranks per channel
  uint32_t banks = 8;    // banks per rank
  uint32_t rows = 0;     // rows per bank
  uint32_t columns = 0;  // columns per row (one column = device_width_bits per device)
  uint32_t device_width_bits = 16;
  uint32_t bus_width_bits = 64;  // data bus width of one channel
  uint32_t burst_length = 8;     // BL: transfers per column command

  // Timing, in DRAM clock cycles (tCK) except tCK_ns.
  double tCK_ns = 0.0;
  uint32_t CL = 0;     // read command -> first read data
  uint32_t CWL = 0;    // write command -> first write data
  uint32_t tRCD = 0;   // activate -> read/write, same bank
  uint32_t tRP = 0;    // precharge -> activate, same bank
  uint32_t tRAS = 0;   // activate -> precharge, same bank
  uint32_t tRC = 0;    // activate -> activate, same bank
  uint32_t tRRD = 0;   // activate -> activate, different banks of a rank
  uint32_t tFAW = 0;   // window that holds at most four activates per rank
  uint32_t tWR = 0;    // end of write data -> precharge
  uint32_t tWTR = 0;   // end of write data -> read, same rank
  uint32_t tRTP = 0;   // read -> precharge
  uint32_t tCCD = 0;   // column command -> column command, same rank
  uint32_t tRTRS = 0;  // data-bus turnaround between ranks
  uint32_t tRFC = 0;   // refresh -> activate (the rank is busy)
  uint32_t tREFI = 0;  // average interval between refreshes

  // Currents per device (Micron TN-41-01 names) and supply.
  double VDD_V = 0.0;
  double IDD0_mA = 0.0;        // one activate-precharge cycle every tRC
  double IDD2N_mA = 0.0;       // precharge standby
  double IDD3N_mA = 0.0;       // active standby
  double IDD4R_mA = 0.0;       // burst read
  double IDD4W_mA = 0.0;       // burst write
  double IDD5_mA = 0.0;        // burst refresh
  double io_pJ_per_bit = 0.0;  // flat I/O + termination energy per data bit moved (0 = core only)

  // Controller.
  uint32_t queue_depth_bursts = 32;  // per-channel transaction queue, in bursts
  // Fields from the most to the least significant bit of the burst address
  // (the byte address without its offset inside one burst).
  std::vector<AddressField> address_mapping = {AddressField::kRow, AddressField::kBank, AddressField::kRank,
                                               AddressField::kColumn, AddressField::kChannel};
  bool refresh = true;

  // Derived quantities.
  uint32_t burst_cycles() const { return burst_length / 2; }  // tBURST: data cycles per column command
  uint32_t devices_per_rank() const { return bus_width_bits / device_width_bits; }
  uint32_t bus_bytes() const { return bus_width_bits / 8; }
  uint32_t burst_bytes() const { return bus_bytes() * burst_length; }  // bytes per column command
  uint32_t bursts_per_row() const { return columns / burst_length; }
  uint64_t row_bytes() const { return uint64_t{columns} * bus_bytes(); }  // one row across the rank
  uint64_t capacity_bytes() const { return uint64_t{channels} * ranks * banks * rows * row_bytes(); }
  // Peak data rate of all channels: two transfers of bus_bytes per tCK.
  double peak_bandwidth_GBps() const { return channels * 2.0 * bus_bytes() / tCK_ns; }

  // Checks every value (positive, powers of two, consistent timing). Throws
  // Error naming the field.
  void validate() const;
};

// Parses a preset. `origin` names the file in error messages. Every key of the
// schema must be present and no other key may appear. Throws Error.
DramConfig parse_dram_config(std::string_view yaml_text, const std::string& origin);
DramConfig load_dram_config(const std::filesystem::path& path);

// The mapping as text, e.g. "row:bank:rank:column:channel", and back.
std::string address_mapping_to_string(const std::vector<AddressField>& mapping);
std::vector<AddressField> parse_address_mapping(const std::string& text);  // throws Error

// Finds a preset: `name_or_path` is either an existing file path, or a preset
// name looked up as <dir>/NAME.yaml in each of `search_dirs` in turn. Throws
// Error listing the directories searched and the presets found there.
std::filesystem::path find_dram_preset(const std::string& name_or_path,
                                       const std::vector<std::filesystem::path>& search_dirs);

// The resolved configuration as YAML text in the preset schema (loads back to
// the same values).
std::string dram_config_to_yaml(const DramConfig& config);

}  // namespace edrnr::sim
