// A small command-line flag parser: --name value and --name=value, with
// errors that name the flag. Used by the transtick command and by the
// daemons.
#ifndef TRANSTICK_COMMON_FLAGS_H_
#define TRANSTICK_COMMON_FLAGS_H_

#include <array>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "absl/status/statusor.h"

namespace transtick {

class Flags {
 public:
  // Parses argv[first..]; every flag must be in `known`. Flags in `switches`
  // take no value.
  static absl::StatusOr<Flags> Parse(int argc, char** argv, int first,
                                     const std::set<std::string>& known,
                                     const std::set<std::string>& switches = {});

  bool Has(const std::string& name) const { return values_.count(name) > 0; }
  std::string Get(const std::string& name, const std::string& fallback = "") const;
  absl::StatusOr<double> GetDouble(const std::string& name, double fallback) const;
  absl::StatusOr<int> GetInt(const std::string& name, int fallback) const;
  absl::StatusOr<bool> GetOnOff(const std::string& name, bool fallback) const;
  // "WxH" (image size) or "XxYxZ" with `n` parts.
  absl::StatusOr<std::vector<int>> GetDims(const std::string& name, int n) const;
  // "a,b,c".
  absl::StatusOr<std::array<double, 3>> GetTriple(const std::string& name) const;
  const std::vector<std::string>& positional() const { return positional_; }

 private:
  std::map<std::string, std::string> values_;
  std::vector<std::string> positional_;
};

}  // namespace transtick

#endif  // TRANSTICK_COMMON_FLAGS_H_
