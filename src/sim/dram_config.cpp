#include "sim/dram_config.h"

#include <fmt/format.h>
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <set>
#include <sstream>
#include <utility>

#include "core/error.h"
#include "core/file_io.h"
#include "core/limits.h"

namespace edrnr::sim {
namespace {

bool is_power_of_two(uint64_t v) { return v != 0 && (v & (v - 1)) == 0; }

// Reads the keys of one YAML map, remembering which were used, so that a
// missing key and an unknown key both give an error naming the key.
class MapReader {
 public:
  MapReader(const YAML::Node& node, std::string path, const std::string& origin)
      : node_(node), path_(std::move(path)), origin_(origin) {
    if (!node_ || !node_.IsMap()) fail("{}: '{}' must be a map of keys to values", origin_, path_);
  }

  YAML::Node child(const std::string& key) {
    YAML::Node n = node_[key];
    if (!n) fail("{}: missing key '{}'", origin_, full(key));
    used_.insert(key);
    return n;
  }

  template <class T>
  T get(const std::string& key) {
    YAML::Node n = child(key);
    if (!n.IsScalar()) fail("{}: '{}' must be a single value", origin_, full(key));
    try {
      return n.as<T>();
    } catch (const YAML::Exception&) {
      fail("{}: '{}' has the value '{}', which is not a valid {}", origin_, full(key), n.Scalar(), type_name<T>());
    }
  }

  uint32_t get_u32(const std::string& key) {
    YAML::Node n = child(key);
    std::string s = n.IsScalar() ? n.Scalar() : "";
    if (s.empty() || s.find_first_not_of("0123456789") != std::string::npos || s.size() > 9) {
      fail("{}: '{}' must be a whole number below 10^9, got '{}'", origin_, full(key), s);
    }
    return static_cast<uint32_t>(std::stoul(s));
  }

  // Throws if the map has a key that was never read.
  void check_no_unknown_keys() const {
    for (const auto& kv : node_) {
      std::string key = kv.first.as<std::string>();
      if (!used_.count(key)) fail("{}: unknown key '{}'", origin_, full(key));
    }
  }

  std::string full(const std::string& key) const { return path_.empty() ? key : path_ + "." + key; }

 private:
  template <class T>
  static const char* type_name() {
    if constexpr (std::is_same_v<T, double>) return "number";
    if constexpr (std::is_same_v<T, bool>) return "boolean (true/false)";
    return "string";
  }

  YAML::Node node_;
  std::string path_;
  const std::string& origin_;
  std::set<std::string> used_;
};

const char* field_name(AddressField f) {
  switch (f) {
    case AddressField::kChannel:
      return "channel";
    case AddressField::kRank:
      return "rank";
    case AddressField::kBank:
      return "bank";
    case AddressField::kRow:
      return "row";
    case AddressField::kColumn:
      return "column";
  }
  return "?";
}

}  // namespace

std::string address_mapping_to_string(const std::vector<AddressField>& mapping) {
  std::string s;
  for (size_t i = 0; i < mapping.size(); ++i) {
    if (i) s += ':';
    s += field_name(mapping[i]);
  }
  return s;
}

std::vector<AddressField> parse_address_mapping(const std::string& text) {
  const AddressField all[] = {AddressField::kChannel, AddressField::kRank, AddressField::kBank, AddressField::kRow,
                              AddressField::kColumn};
  std::vector<AddressField> out;
  std::stringstream ss(text);
  std::string part;
  while (std::getline(ss, part, ':')) {
    auto it = std::find_if(std::begin(all), std::end(all), [&](AddressField f) { return part == field_name(f); });
    if (it == std::end(all)) {
      fail("address mapping '{}': unknown field '{}' (fields are row, bank, rank, column, channel)", text, part);
    }
    if (std::find(out.begin(), out.end(), *it) != out.end()) {
      fail("address mapping '{}': field '{}' appears twice", text, part);
    }
    out.push_back(*it);
  }
  if (out.size() != 5) {
    fail("address mapping '{}' must name each of row, bank, rank, column, channel once, separated by ':'", text);
  }
  return out;
}

void DramConfig::validate() const {
  auto pow2 = [](const char* field, uint64_t v) {
    if (!is_power_of_two(v)) fail("DRAM config: {} = {} must be a power of two", field, v);
  };
  pow2("structure.channels", channels);
  pow2("structure.ranks", ranks);
  pow2("structure.banks", banks);
  pow2("structure.rows", rows);
  pow2("structure.columns", columns);
  pow2("structure.device_width_bits", device_width_bits);
  pow2("structure.bus_width_bits", bus_width_bits);
  pow2("structure.burst_length", burst_length);
  if (burst_length < 2) fail("DRAM config: structure.burst_length = {} must be at least 2", burst_length);
  if (columns < burst_length) {
    fail("DRAM config: structure.columns = {} is smaller than the burst length {}", columns, burst_length);
  }
  if (bus_width_bits < 8 || bus_width_bits < device_width_bits) {
    fail("DRAM config: structure.bus_width_bits = {} must be at least 8 and at least device_width_bits = {}",
         bus_width_bits, device_width_bits);
  }
  if (!(tCK_ns >= limits::kMinDramTckNs && tCK_ns <= limits::kMaxDramTckNs))
    fail("DRAM config: timing.tCK_ns = {} must be between {} and {} ns (limit; DDR3 parts run at 0.94 to 3.3 ns)",
         tCK_ns, limits::kMinDramTckNs, limits::kMaxDramTckNs);
  auto positive = [](const char* field, uint32_t v) {
    if (v == 0) fail("DRAM config: {} must be at least 1 cycle", field);
  };
  positive("timing.CL", CL);
  positive("timing.CWL", CWL);
  positive("timing.tRCD", tRCD);
  positive("timing.tRP", tRP);
  positive("timing.tRAS", tRAS);
  positive("timing.tRRD", tRRD);
  positive("timing.tCCD", tCCD);
  positive("timing.tRTP", tRTP);
  positive("timing.tRFC", tRFC);
  // Every timing value is bounded, so a wait between commands stays short of a hang.
  const std::pair<const char*, uint32_t> timings[] = {
      {"timing.CL", CL},       {"timing.CWL", CWL},   {"timing.tRCD", tRCD},  {"timing.tRP", tRP},
      {"timing.tRAS", tRAS},   {"timing.tRC", tRC},   {"timing.tRRD", tRRD},  {"timing.tFAW", tFAW},
      {"timing.tWR", tWR},     {"timing.tWTR", tWTR}, {"timing.tRTP", tRTP},  {"timing.tCCD", tCCD},
      {"timing.tRTRS", tRTRS}, {"timing.tRFC", tRFC}, {"timing.tREFI", tREFI}};
  for (const auto& [field, v] : timings)
    if (v > limits::kMaxDramTimingCycles)
      fail("DRAM config: {} = {} cycles is over the limit of {} cycles", field, v, limits::kMaxDramTimingCycles);
  if (queue_depth_bursts > limits::kMaxDramQueueBursts)
    fail("DRAM config: controller.queue_depth_bursts = {} is over the limit of {}", queue_depth_bursts,
         limits::kMaxDramQueueBursts);
  if (uint64_t{channels} * ranks * banks > limits::kMaxDramBanks)
    fail("DRAM config: {} channels x {} ranks x {} banks is over the limit of {} banks", channels, ranks, banks,
         limits::kMaxDramBanks);
  if (tRC < tRAS + tRP) fail("DRAM config: timing.tRC = {} is less than tRAS + tRP = {}", tRC, tRAS + tRP);
  if (refresh && tREFI <= tRFC) fail("DRAM config: timing.tREFI = {} must exceed tRFC = {}", tREFI, tRFC);
  if (!(VDD_V > 0.0)) fail("DRAM config: power.VDD_V = {} must be positive", VDD_V);
  auto nonneg = [](const char* field, double v) {
    if (!(v >= 0.0)) fail("DRAM config: {} = {} must not be negative", field, v);
  };
  nonneg("power.IDD0_mA", IDD0_mA);
  nonneg("power.IDD2N_mA", IDD2N_mA);
  nonneg("power.IDD3N_mA", IDD3N_mA);
  nonneg("power.io_pJ_per_bit", io_pJ_per_bit);
  if (IDD4R_mA < IDD3N_mA) fail("DRAM config: power.IDD4R_mA = {} is below IDD3N_mA = {}", IDD4R_mA, IDD3N_mA);
  if (IDD4W_mA < IDD3N_mA) fail("DRAM config: power.IDD4W_mA = {} is below IDD3N_mA = {}", IDD4W_mA, IDD3N_mA);
  if (IDD5_mA < IDD3N_mA) fail("DRAM config: power.IDD5_mA = {} is below IDD3N_mA = {}", IDD5_mA, IDD3N_mA);
  if (IDD0_mA * tRC < IDD3N_mA * tRAS + IDD2N_mA * (tRC - tRAS)) {
    fail("DRAM config: power.IDD0_mA = {} is too small: IDD0*tRC must be at least IDD3N*tRAS + IDD2N*(tRC-tRAS)",
         IDD0_mA);
  }
  if (queue_depth_bursts == 0) fail("DRAM config: controller.queue_depth_bursts must be at least 1");
  if (address_mapping.size() != 5) fail("DRAM config: controller.address_mapping must name five fields");
  if (uint64_t{rows} * banks * ranks * channels * columns > (uint64_t{1} << 40)) {
    fail("DRAM config: the organisation describes more than 2^40 columns");
  }
}

DramConfig parse_dram_config(std::string_view yaml_text, const std::string& origin) {
  YAML::Node root;
  try {
    root = YAML::Load(std::string(yaml_text));
  } catch (const YAML::Exception& e) {
    fail("{}: YAML syntax error at line {}: {}", origin, e.mark.line + 1, e.msg);
  }
  DramConfig c;
  MapReader top(root, "", origin);
  c.name = top.get<std::string>("name");
  c.source = top.get<std::string>("source");

  MapReader s(top.child("structure"), "structure", origin);
  c.channels = s.get_u32("channels");
  c.ranks = s.get_u32("ranks");
  c.banks = s.get_u32("banks");
  c.rows = s.get_u32("rows");
  c.columns = s.get_u32("columns");
  c.device_width_bits = s.get_u32("device_width_bits");
  c.bus_width_bits = s.get_u32("bus_width_bits");
  c.burst_length = s.get_u32("burst_length");
  s.check_no_unknown_keys();

  MapReader t(top.child("timing"), "timing", origin);
  c.tCK_ns = t.get<double>("tCK_ns");
  c.CL = t.get_u32("CL");
  c.CWL = t.get_u32("CWL");
  c.tRCD = t.get_u32("tRCD");
  c.tRP = t.get_u32("tRP");
  c.tRAS = t.get_u32("tRAS");
  c.tRC = t.get_u32("tRC");
  c.tRRD = t.get_u32("tRRD");
  c.tFAW = t.get_u32("tFAW");
  c.tWR = t.get_u32("tWR");
  c.tWTR = t.get_u32("tWTR");
  c.tRTP = t.get_u32("tRTP");
  c.tCCD = t.get_u32("tCCD");
  c.tRTRS = t.get_u32("tRTRS");
  c.tRFC = t.get_u32("tRFC");
  c.tREFI = t.get_u32("tREFI");
  t.check_no_unknown_keys();

  MapReader p(top.child("power"), "power", origin);
  c.VDD_V = p.get<double>("VDD_V");
  c.IDD0_mA = p.get<double>("IDD0_mA");
  c.IDD2N_mA = p.get<double>("IDD2N_mA");
  c.IDD3N_mA = p.get<double>("IDD3N_mA");
  c.IDD4R_mA = p.get<double>("IDD4R_mA");
  c.IDD4W_mA = p.get<double>("IDD4W_mA");
  c.IDD5_mA = p.get<double>("IDD5_mA");
  c.io_pJ_per_bit = p.get<double>("io_pJ_per_bit");
  p.check_no_unknown_keys();

  MapReader k(top.child("controller"), "controller", origin);
  c.queue_depth_bursts = k.get_u32("queue_depth_bursts");
  try {
    c.address_mapping = parse_address_mapping(k.get<std::string>("address_mapping"));
  } catch (const Error& e) {
    fail("{}: controller.{}", origin, e.what());
  }
  c.refresh = k.get<bool>("refresh");
  k.check_no_unknown_keys();
  top.check_no_unknown_keys();

  try {
    c.validate();
  } catch (const Error& e) {
    fail("{}: {}", origin, e.what());
  }
  return c;
}

DramConfig load_dram_config(const std::filesystem::path& path) {
  return parse_dram_config(read_file_text(path), path.string());
}

std::filesystem::path find_dram_preset(const std::string& name_or_path,
                                       const std::vector<std::filesystem::path>& search_dirs) {
  namespace fs = std::filesystem;
  if (name_or_path.empty()) fail("no DRAM preset name given");
  std::error_code ec;
  if (fs::is_regular_file(name_or_path, ec)) return name_or_path;
  bool looks_like_path = name_or_path.find('/') != std::string::npos || name_or_path.ends_with(".yaml");
  if (looks_like_path) fail("DRAM preset file '{}' does not exist", name_or_path);
  std::set<std::string> available;
  std::string searched;
  for (const fs::path& dir : search_dirs) {
    fs::path candidate = dir / (name_or_path + ".yaml");
    if (fs::is_regular_file(candidate, ec)) return candidate;
    if (!searched.empty()) searched += ", ";
    searched += dir.string();
    if (fs::is_directory(dir, ec)) {
      for (const auto& entry : fs::directory_iterator(dir, ec)) {
        if (entry.path().extension() == ".yaml") available.insert(entry.path().stem().string());
      }
    }
  }
  std::string names;
  for (const std::string& n : available) names += (names.empty() ? "" : ", ") + n;
  fail("no DRAM preset named '{}' (searched {}; available: {})", name_or_path, searched.empty() ? "nothing" : searched,
       names.empty() ? "none" : names);
}

std::string dram_config_to_yaml(const DramConfig& c) {
  YAML::Emitter out;
  out << YAML::BeginMap;
  out << YAML::Key << "name" << YAML::Value << YAML::DoubleQuoted << c.name;
  out << YAML::Key << "source" << YAML::Value << YAML::DoubleQuoted << c.source;
  out << YAML::Key << "structure" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "channels" << YAML::Value << c.channels;
  out << YAML::Key << "ranks" << YAML::Value << c.ranks;
  out << YAML::Key << "banks" << YAML::Value << c.banks;
  out << YAML::Key << "rows" << YAML::Value << c.rows;
  out << YAML::Key << "columns" << YAML::Value << c.columns;
  out << YAML::Key << "device_width_bits" << YAML::Value << c.device_width_bits;
  out << YAML::Key << "bus_width_bits" << YAML::Value << c.bus_width_bits;
  out << YAML::Key << "burst_length" << YAML::Value << c.burst_length;
  out << YAML::EndMap;
  out << YAML::Key << "timing" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "tCK_ns" << YAML::Value << c.tCK_ns;
  const std::pair<const char*, uint32_t> timing[] = {
      {"CL", c.CL},     {"CWL", c.CWL},   {"tRCD", c.tRCD},   {"tRP", c.tRP},   {"tRAS", c.tRAS},
      {"tRC", c.tRC},   {"tRRD", c.tRRD}, {"tFAW", c.tFAW},   {"tWR", c.tWR},   {"tWTR", c.tWTR},
      {"tRTP", c.tRTP}, {"tCCD", c.tCCD}, {"tRTRS", c.tRTRS}, {"tRFC", c.tRFC}, {"tREFI", c.tREFI}};
  for (const auto& [key, v] : timing) out << YAML::Key << key << YAML::Value << v;
  out << YAML::EndMap;
  out << YAML::Key << "power" << YAML::Value << YAML::BeginMap;
  const std::pair<const char*, double> power[] = {
      {"VDD_V", c.VDD_V},       {"IDD0_mA", c.IDD0_mA},   {"IDD2N_mA", c.IDD2N_mA}, {"IDD3N_mA", c.IDD3N_mA},
      {"IDD4R_mA", c.IDD4R_mA}, {"IDD4W_mA", c.IDD4W_mA}, {"IDD5_mA", c.IDD5_mA},   {"io_pJ_per_bit", c.io_pJ_per_bit}};
  for (const auto& [key, v] : power) out << YAML::Key << key << YAML::Value << v;
  out << YAML::EndMap;
  out << YAML::Key << "controller" << YAML::Value << YAML::BeginMap;
  out << YAML::Key << "queue_depth_bursts" << YAML::Value << c.queue_depth_bursts;
  out << YAML::Key << "address_mapping" << YAML::Value << address_mapping_to_string(c.address_mapping);
  out << YAML::Key << "refresh" << YAML::Value << c.refresh;
  out << YAML::EndMap;
  out << YAML::EndMap;
  return std::string(out.c_str()) + "\n";
}

}  // namespace edrnr::sim
