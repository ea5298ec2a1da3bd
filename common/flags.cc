#include "flags.h"

#include <cmath>
#include <cstdlib>
#include <limits>

#include "absl/strings/numbers.h"
#include "absl/strings/str_cat.h"
#include "absl/strings/str_split.h"

namespace transtick {

absl::StatusOr<Flags> Flags::Parse(int argc, char** argv, int first,
                                   const std::set<std::string>& known,
                                   const std::set<std::string>& switches) {
  CommandDoc doc;
  doc.name = argc > 0 ? std::string(argv[0]) : "";
  if (auto slash = doc.name.rfind('/'); slash != std::string::npos) doc.name.erase(0, slash + 1);
  doc.args = "ARGS";
  doc.max_args = std::numeric_limits<int>::max();
  for (const std::string& name : known) doc.flags.push_back({name, "VALUE", ""});
  for (const std::string& name : switches) doc.flags.push_back({name, "", ""});
  return Parse(argc, argv, first, doc);
}

absl::StatusOr<Flags> Flags::Parse(int argc, char** argv, int first, const CommandDoc& doc) {
  for (int i = first; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg == "--help" || arg == "-h") {
      Flags help;
      help.values_["help"] = "on";
      return help;
    }
  }
  Flags f;
  const auto find = [&](const std::string& name) -> const FlagDoc* {
    for (const FlagDoc& d : doc.flags) {
      if (d.name == name) return &d;
    }
    return nullptr;
  };
  const std::string see = absl::StrCat(" (see ", doc.name, " --help)");
  for (int i = first; i < argc; ++i) {
    const std::string arg = argv[i];
    if (arg.size() > 1 && arg[0] == '-' && arg.rfind("--", 0) != 0) {
      return absl::InvalidArgumentError(
          absl::StrCat("'", arg, "' is not a flag: flags start with --", see));
    }
    if (arg.rfind("--", 0) != 0 || arg == "--") {
      if (static_cast<int>(f.positional_.size()) >= doc.max_args) {
        return absl::InvalidArgumentError(
            doc.max_args == 0
                ? absl::StrCat("unexpected argument '", arg, "': ", doc.name,
                               " takes flags only", see)
                : absl::StrCat("unexpected argument '", arg, "' after ", doc.args, see));
      }
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
    const FlagDoc* d = find(name);
    if (d == nullptr) return absl::InvalidArgumentError(absl::StrCat("unknown flag --", name, see));
    if (f.values_.count(name)) {
      return absl::InvalidArgumentError(absl::StrCat("--", name, " is given twice"));
    }
    if (d->value.empty()) {
      f.values_[name] = has_value ? value : "on";
      continue;
    }
    if (!has_value) {
      if (i + 1 >= argc) {
        return absl::InvalidArgumentError(absl::StrCat("--", name, " needs a value (", d->value, ")"));
      }
      value = argv[++i];
    }
    f.values_[name] = value;
  }
  if (static_cast<int>(f.positional_.size()) < doc.min_args) {
    return absl::InvalidArgumentError(absl::StrCat(doc.name, " needs ", doc.args, see));
  }
  return f;
}

std::string Usage(const CommandDoc& doc) {
  std::string out = absl::StrCat("usage: ", doc.name, doc.args.empty() ? "" : " ", doc.args,
                                 doc.flags.empty() ? "" : " [flags]", "\n\n", doc.summary, "\n");
  if (!doc.flags.empty()) out += "\nflags:\n";
  for (const FlagDoc& d : doc.flags) {
    std::string head = absl::StrCat("  --", d.name, d.value.empty() ? "" : " ", d.value);
    std::vector<std::string> lines = absl::StrSplit(d.help, '\n');
    constexpr size_t kColumn = 28;
    for (size_t i = 0; i < lines.size(); ++i) {
      if (i == 0 && head.size() + 2 <= kColumn) {
        out += absl::StrCat(head, std::string(kColumn - head.size(), ' '), lines[i], "\n");
      } else {
        if (i == 0) out += head + "\n";
        out += absl::StrCat(std::string(kColumn, ' '), lines[i], "\n");
      }
    }
  }
  out += absl::StrCat("  --help                    this text\n");
  if (!doc.epilog.empty()) out += absl::StrCat("\n", doc.epilog, "\n");
  return out;
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
