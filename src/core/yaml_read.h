#pragma once
// Reading config maps from yaml-cpp nodes with errors that name the place:
// the chip's and the simulator's YAML presets share these.
#include <yaml-cpp/yaml.h>

#include <algorithm>
#include <initializer_list>
#include <string>

#include "core/error.h"

namespace edrnr {

// The scalar v as a T; Error "where: expected <expected>" when v is not a
// scalar, "where: 'text' is not <expected>" when it does not convert.
template <class T>
T yaml_scalar(const YAML::Node& v, const std::string& where, const char* expected) {
  if (!v.IsScalar()) fail("{}: expected {}", where, expected);
  try {
    return v.as<T>();
  } catch (const YAML::Exception&) {
    fail("{}: '{}' is not {}", where, v.Scalar(), expected);
  }
}

// Calls f(key, value, "where.key") for each entry of the map `node`; a node
// that is not a map, or a key not in `known`, is an Error naming `where`.
template <class F>
void yaml_for_each_key(const YAML::Node& node, const std::string& where, std::initializer_list<const char*> known,
                       F f) {
  if (!node.IsMap()) fail("{}: expected a map", where);
  for (const auto& kv : node) {
    const std::string key = kv.first.as<std::string>();
    if (std::none_of(known.begin(), known.end(), [&](const char* k) { return key == k; })) {
      std::string list;
      for (const char* k : known) list += std::string(list.empty() ? "" : ", ") + k;
      fail("{}: unknown key '{}' (known: {})", where, key, list);
    }
    f(key, kv.second, where + "." + key);
  }
}

}  // namespace edrnr
