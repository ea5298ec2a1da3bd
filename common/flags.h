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

// What a command takes, for parsing and for its --help: the one place a
// flag is declared.
struct FlagDoc {
  std::string name;   // without the leading "--"
  std::string value;  // what follows it ("FILE", "N"); empty for a switch
  std::string help;   // may hold '\n' for more lines
};
struct CommandDoc {
  std::string name;      // "transtick render"
  std::string args;      // the positional arguments' synopsis: "JOB.json", or ""
  std::string summary;   // one paragraph
  int min_args = 0;      // positional arguments required ...
  int max_args = 0;      // ... and allowed
  std::vector<FlagDoc> flags;
  std::string epilog;    // after the flags: notes, examples
};

// The --help text of a command: synopsis, summary, each flag with its help.
std::string Usage(const CommandDoc& doc);

class Flags {
 public:
  // Parses argv[first..] as `doc` declares: every flag must be one of its
  // flags, a switch takes no value, and the positional arguments must number
  // within [min_args, max_args]. "--help" or "-h" anywhere gives flags that
  // only have "help" (the command prints Usage and exits 0); any other word
  // starting with a single '-' is refused, as is a flag given twice.
  static absl::StatusOr<Flags> Parse(int argc, char** argv, int first, const CommandDoc& doc);

  // Parses argv[first..] as the CommandDoc of the program argv[0] with the
  // flags `known` (each taking a value) and `switches` (none) and any number
  // of positional arguments.
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
