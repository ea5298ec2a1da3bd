// Progress of a render or a job, told to a person on stderr: on a terminal
// one line redrawn in place with the percentage and the time left; in a pipe
// or a log (not a terminal) a plain line every few seconds, so a long render
// shows in `docker logs` or a CI log too.
#ifndef TRANSTICK_CLI_PROGRESS_H_
#define TRANSTICK_CLI_PROGRESS_H_

#include <chrono>
#include <cstdio>
#include <string>

#include "absl/base/thread_annotations.h"
#include "absl/synchronization/mutex.h"

namespace transtick {

class Progress {
 public:
  enum class Style {
    kTerminal,  // a line redrawn in place
    kLines,     // a line now and then
    kOff,       // nothing but Say
  };
  // The style for stderr: kTerminal when it is a terminal, else kLines;
  // kOff when `quiet`.
  static Style ForStderr(bool quiet);

  // The interval of kLines' lines: $TRANSTICK_PROGRESS_EVERY seconds
  // (0.01 to 86400), 5 by default.
  static std::chrono::milliseconds LinesInterval();

  explicit Progress(Style style, std::chrono::milliseconds every = LinesInterval(),
                    std::FILE* out = stderr);
  ~Progress();
  Progress(const Progress&) = delete;
  Progress& operator=(const Progress&) = delete;

  // `fraction` of the whole work is done (in [0, 1]); `what` says where
  // ("job-3 frame 2/30"). The time elapsed counts from construction; the
  // time left follows the rate since the first Update (so time spent in a
  // queue or loading does not inflate it). Thread-safe.
  void Update(double fraction, const std::string& what);
  // A line that stays (a frame saved, a warning), in every style but kOff.
  void Say(const std::string& line);
  // A line that stays even in kOff (warnings).
  void Warn(const std::string& line);
  // Clears the terminal line, if any.
  void Finish();

  // "1.2 s", "3 min 05 s", "1 h 02 min": how the time left is written.
  static std::string Duration(double seconds);

 private:
  void ClearLocked() ABSL_EXCLUSIVE_LOCKS_REQUIRED(mu_);

  const Style style_;
  const std::chrono::milliseconds every_;
  std::FILE* const out_;
  absl::Mutex mu_;
  bool started_ ABSL_GUARDED_BY(mu_) = false;     // an Update came
  bool line_open_ ABSL_GUARDED_BY(mu_) = false;  // a terminal line to clear
  const std::chrono::steady_clock::time_point created_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point first_ ABSL_GUARDED_BY(mu_);  // the first Update
  double first_fraction_ ABSL_GUARDED_BY(mu_) = 0;
  std::chrono::steady_clock::time_point last_ ABSL_GUARDED_BY(mu_);   // the last line
};

}  // namespace transtick

#endif  // TRANSTICK_CLI_PROGRESS_H_
