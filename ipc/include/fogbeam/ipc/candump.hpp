// fogbeam — candump log files (can-utils `candump -L`, also written by `candump -l`; and what
// candump prints on screen, redirected to a file) and a replayer that feeds their frames at the
// recorded pace.
//
// One frame per line (can-utils lib.c, sprint_canframe / parse_canframe; candump.c):
//   (1700000000.123456) vcan0 123#DEADBEEF         classic frame, 11-bit id: 3 hex digits
//   (1700000000.123456) vcan0 1F334455#00          29-bit id: 8 hex digits
//   (1700000000.123456) vcan0 123#R                remote frame, length 0
//   (1700000000.123456) vcan0 123#R4               remote frame requesting 4 bytes
//   (1700000000.123456) vcan0 123##1112233         CAN FD: '##', one hex flags digit
//                                                  (0x1 BRS, 0x2 ESI), then the data
// Data is 0–8 bytes (classic) or a valid CAN FD length (0–8, 12, 16, 20, 24, 32, 48, 64), two
// hex digits per byte; '.' between bytes is accepted (cansend's notation). Also accepted:
// a classic 8-byte frame's raw DLC 9–F after '_' ("123#0011223344556677_C", printed for
// CAN_CTRLMODE_CC_LEN8_DLC; ignored), and a trailing direction token "R"/"T" (candump -x).
// Rejected with a message saying so: error frames (candump -e, id with CAN_ERR_FLAG) and
// CAN XL frames ('###').
//
// candump's screen format (no -l/-L; can-utils candump.c and lib.c snprintf_long_canframe) is
// read too, line by line (a line is in it when one of its tokens is a length "[n]"):
//   " (1700000000.123456)  can0  123   [4]  DE AD BE EF"     -t a: seconds since the epoch
//   " (2023-11-14 22:13:20.250000)  can0  123   [1]  01"     -t A: a date, taken as UTC
//   "  can0  1F334455   [2]  00 11"                          no -t: no timestamp (below)
//   "  can0  123   [4]  remote request"                      a remote frame of length 4
//   "  can0  RX B -  123  [12]  00 11 … BB"                  -x: direction, CAN FD BRS/ESI; two
//                                                            length digits: CAN FD
//   "  can0  123   {C}  00 11 22 33 44 55 66 77"             -8: the raw DLC (9-F: 8 bytes)
//   "… [2]  41 42   'AB'"                                    -a: the ASCII column (ignored)
// A line without a timestamp gets the previous line's (loadCandump; 0 at the start): such a
// capture replays at once. "-t z" times (since the first frame) read as any other; "-t d"
// (the gap since the previous frame) looks the same and cannot be told apart: it is read as
// "-t z" and paces wrongly, so record with -t a, -t A, -t z or -L. Error frames ("ERRORFRAME",
// CAN_ERR_FLAG) are rejected as in -L lines; candump -B (binary bytes) and -S (byte-swapped)
// views are not read ("expected … data byte(s) as hex pairs").
//
// Thread-safety: parsing is reentrant; replayCandump runs on the calling thread.
#pragma once

#include <fogbeam/ipc/can_frame.hpp>
#include <fogbeam/util/result.hpp>

#include <functional>
#include <string>
#include <string_view>
#include <vector>

namespace fogbeam::ipc {

struct CandumpLine {
  double timestamp_s = 0.0;  ///< the logged time, seconds (since the Unix epoch for live captures)
  std::string interface;     ///< "can0", "vcan0", …
  CanFrame frame;            ///< frame.timestamp_s equals timestamp_s
  /// false: a screen-format line without a timestamp (timestamp_s 0 from parseCandumpLine;
  /// loadCandump gives it the previous line's)
  bool timed = true;
};

/// Parses one log line (without its line ending), -L or screen format. Errors read "expected …,
/// found …" without a file name; loadCandump prefixes "file:line: ".
[[nodiscard]] Result<CandumpLine> parseCandumpLine(std::string_view line);

/// Reads a whole log. Blank lines and lines starting with '#' are skipped. The first bad line
/// fails the load with "path:line: expected …, found …"; nothing half-read is returned.
[[nodiscard]] Result<std::vector<CandumpLine>> loadCandump(const std::string& path);

/// Passes the lines to `sink` in order, sleeping so that the gaps between their timestamps
/// are reproduced divided by `speed`: 1 = recorded pace, 2 = twice as fast, 0 (or negative,
/// or not finite) = as fast as possible. Times are measured from the first line, against a
/// steady clock, so sleeping late does not accumulate; a line whose timestamp is earlier
/// than an earlier line's is sent at once. A single wait is capped at one year. Stops early when `sink` returns false. Blocks the calling
/// thread for the length of the log / speed.
void replayCandump(const std::vector<CandumpLine>& lines, double speed,
                   const std::function<bool(const CandumpLine&)>& sink);

}  // namespace fogbeam::ipc
