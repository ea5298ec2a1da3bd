#include "flags.h"

#include <cmath>
#include <cstdlib>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace transtick {

absl::StatusOr<Flags> Flags::Parse(int argc, char** argv, int first,
                                   const std::set<std::string>& known,
                                   const std::set<std::string>& switches) {
  Flags f;
  for (int i = first; i < argc; ++i) {
    std::string arg = argv[i];
    if (arg.rfind("--", 0) != 0) {
      f.positional_.push_back(arg);
      continue;
    }
    std::string name = arg.substr(2), value;
    bool has_value = false;
    if (auto eq = name.find('='); eq != std::string::npos) {
      value = name.substr(eq + 1);
      name = name.substr(0, eq);
      has_value = true;
    }
    if (!known.count(name) && !switches.count(name)) {
      return absl::InvalidArgumentError(absl::StrCat("unknown flag --", name));
    }
    if (switches.count(name)) {
      f.values_[name] = has_value ? value : "on";
      continue;
    }
    if (!has_value) {
      if (i + 1 >= argc)
        return absl::InvalidArgumentError(absl::StrCat("--", name, " needs a value"));
      value = argv[++i];
    }
    f.values_[name] = value;
  }
  return f;
}

std::string Flags::Get(const std::string& name, const std::string& fallback) const {
  auto it = values_.find(name);
  return it == values_.end() ? fallback : it->second;
}

absl::StatusOr<double> Flags::GetDouble(const std::string& name, double fallback) const {
  if (!Has(name)) return fallback;
  double v;
  if (!absl::SimpleAtod(Get(name), &v) || !std::isfinite(v)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", name, ": '", Get(name), "' is not a number"));
  }
  return v;
}

absl::StatusOr<int> Flags::GetInt(const std::string& name, int fallback) const {
  if (!Has(name)) return fallback;
  int v;
  if (!absl::SimpleAtoi(Get(name), &v)) {
    return absl::InvalidArgumentError(
        absl::StrCat("--", name, ": '", Get(name), "' is not an integer"));
  }
  return v;
}

absl::StatusOr<bool> Flags::GetOnOff(const std::string& name, bool fallback) const {
  if (!Has(name)) return fallback;
  std::string v = Get(name);
  if (v == "on" || v == "true" || v == "1") return true;
  if (v == "off" || v == "false" || v == "0") return false;
  return absl::InvalidArgumentError(absl::StrCat("--", name, ": '", v, "' is not on or off"));
}

absl::StatusOr<std::vector<int>> Flags::GetDims(const std::string& name, int n) const {
  std::vector<std::string> parts = absl::StrSplit(Get(name), 'x');
  std::vector<int> out;
  for (const auto& p : parts) {
    int v;
    if (!absl::SimpleAtoi(p, &v)) break;
    out.push_back(v);
  }
  if (static_cast<int>(out.size()) != n || static_cast<int>(parts.size()) != n) {
    return absl::InvalidArgumentError(absl::StrCat("--", name, ": '", Get(name), "' is not ",
                                                   n == 2 ? "WxH" : "XxYxZ",
                                                   " (integers joined by 'x')"));
  }
  return out;
}

absl::StatusOr<std::array<double, 3>> Flags::GetTriple(const std::string& name) const {
  std::vector<std::string> parts = absl::StrSplit(Get(name), ',');
  std::array<double, 3> out;
  if (parts.size() != 3) {
    return absl::InvalidArgumentError(absl::StrCat("--", name, ": '", Get(name), "' is not x,y,z"));
  }
  for (int i = 0; i < 3; ++i) {
    if (!absl::SimpleAtod(parts[i], &out[i]) || !std::isfinite(out[i])) {
      return absl::InvalidArgumentError(
          absl::StrCat("--", name, ": '", Get(name), "' is not x,y,z"));
    }
  }
  return out;
}

}  // namespace transtick
