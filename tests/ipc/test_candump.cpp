// candump -L log lines and candump's screen format: every frame kind, every error, the log file
// reader and the replayer.
#include <fogbeam/ipc/candump.hpp>

#include <gtest/gtest.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <fstream>
#include <unistd.h>
#include <random>
#include <string>
#include <vector>

namespace fogbeam::ipc {
namespace {

const std::string kCanData = std::string(FOGBEAM_TEST_DATA_DIR) + "/can";

CandumpLine parseOk(const std::string& line) {
  Result<CandumpLine> r = parseCandumpLine(line);
  EXPECT_TRUE(r.has_value()) << line << ": " << (r ? "" : r.error().message);
  return r ? *r : CandumpLine{};
}

std::string parseError(const std::string& line) {
  Result<CandumpLine> r = parseCandumpLine(line);
  EXPECT_FALSE(r.has_value()) << "parsed without error: " << line;
  return r ? std::string() : r.error().message;
}

TEST(CandumpLine, ClassicStandardFrame) {
  const CandumpLine l = parseOk("(1700000000.123456) vcan0 123#DEADBEEF");
  EXPECT_NEAR(l.timestamp_s, 1700000000.123456, 1e-6);
  EXPECT_EQ(l.frame.timestamp_s, l.timestamp_s);
  EXPECT_EQ(l.interface, "vcan0");
  EXPECT_EQ(l.frame.id, 0x123u);
  EXPECT_FALSE(l.frame.extended);
  EXPECT_FALSE(l.frame.remote);
  EXPECT_FALSE(l.frame.fd);
  ASSERT_EQ(l.frame.len, 4);
  EXPECT_EQ(l.frame.data[0], 0xDE);
  EXPECT_EQ(l.frame.data[3], 0xEF);
  EXPECT_EQ(l.frame.data[4], 0);
}

TEST(CandumpLine, TimestampKeepsMicroseconds) {
  // Seconds and fraction are read as integers: 0.000001 s steps survive at epoch times.
  const double a = parseOk("(1700000000.000001) can0 123#").timestamp_s;
  const double b = parseOk("(1700000000.000002) can0 123#").timestamp_s;
  EXPECT_NEAR(b - a, 1e-6, 1e-7);
  EXPECT_EQ(parseOk("(0000000012.5) can0 123#").timestamp_s, 12.5);
  EXPECT_EQ(parseOk("(7) can0 123#").timestamp_s, 7.0);
}

TEST(CandumpLine, ExtendedRemoteEmptyAndDottedFrames) {
  const CandumpLine ext = parseOk("(1.0) can0 18FEF121#F6");
  EXPECT_TRUE(ext.frame.extended);
  EXPECT_EQ(ext.frame.id, 0x18FEF121u);
  EXPECT_EQ(ext.frame.len, 1);
  // 8 digits mark the extended format even for a small value.
  const CandumpLine small = parseOk("(1.0) can0 00000123#");
  EXPECT_TRUE(small.frame.extended);
  EXPECT_EQ(small.frame.id, 0x123u);
  EXPECT_EQ(small.frame.len, 0);

  const CandumpLine rtr = parseOk("(1.0) can0 123#R");
  EXPECT_TRUE(rtr.frame.remote);
  EXPECT_EQ(rtr.frame.len, 0);
  const CandumpLine rtr4 = parseOk("(1.0) can0 1FFFFFFF#R4");
  EXPECT_TRUE(rtr4.frame.remote);
  EXPECT_TRUE(rtr4.frame.extended);
  EXPECT_EQ(rtr4.frame.id, 0x1FFFFFFFu);
  EXPECT_EQ(rtr4.frame.len, 4);

  const CandumpLine dotted = parseOk("(1.0) can0 7FF#11.22.33");
  EXPECT_EQ(dotted.frame.id, 0x7FFu);
  ASSERT_EQ(dotted.frame.len, 3);
  EXPECT_EQ(dotted.frame.data[2], 0x33);

  const CandumpLine lower = parseOk("(1.0) can0 7ff#aabb");
  EXPECT_EQ(lower.frame.id, 0x7FFu);
  EXPECT_EQ(lower.frame.data[0], 0xAA);
}

TEST(CandumpLine, CanFdFramesWithFlags) {
  const CandumpLine fd = parseOk("(1.0) can0 123##1112233");
  EXPECT_TRUE(fd.frame.fd);
  EXPECT_TRUE(fd.frame.brs);
  EXPECT_FALSE(fd.frame.esi);
  ASSERT_EQ(fd.frame.len, 3);
  EXPECT_EQ(fd.frame.data[0], 0x11);
  EXPECT_EQ(fd.frame.data[2], 0x33);
  const CandumpLine esi = parseOk("(1.0) can0 12345678##2");
  EXPECT_TRUE(esi.frame.esi);
  EXPECT_FALSE(esi.frame.brs);
  EXPECT_TRUE(esi.frame.extended);
  EXPECT_EQ(esi.frame.len, 0);
  // 64 bytes: the largest FD payload.
  const CandumpLine big = parseOk("(1.0) can0 123##3" + std::string(128, 'A'));
  EXPECT_EQ(big.frame.len, 64);
  EXPECT_TRUE(big.frame.brs && big.frame.esi);
  EXPECT_EQ(big.frame.data[63], 0xAA);
  // Every valid FD length parses.
  for (const int n : {0, 1, 8, 12, 16, 20, 24, 32, 48, 64})
    EXPECT_EQ(parseOk("(1.0) can0 123##0" + std::string(static_cast<std::size_t>(2 * n), '0')).frame.len, n);
}

TEST(CandumpLine, OptionalDlcSuffixAndDirection) {
  const CandumpLine dlc = parseOk("(1.0) can0 123#0011223344556677_C");
  EXPECT_EQ(dlc.frame.len, 8);
  EXPECT_EQ(parseOk("(1.0) can0 123#00 R").frame.len, 1);
  EXPECT_EQ(parseOk("(1.0)\tcan0   123#00  T\r").frame.len, 1);
}

TEST(CandumpErrors, EveryMessage) {
  EXPECT_EQ(parseError(""), "expected a timestamp '(seconds.microseconds)', found the end of the line");
  EXPECT_EQ(parseError("1700000000.0 can0 123#00"),
            "expected a timestamp '(seconds.microseconds)', found '1700000000.0'");
  EXPECT_EQ(parseError("(17x.0) can0 123#00"), "expected a timestamp '(seconds.microseconds)', found '(17x.0)'");
  EXPECT_EQ(parseError("(1.) can0 123#00"), "expected a timestamp '(seconds.microseconds)', found '(1.)'");
  EXPECT_EQ(parseError("(1.0)"),
            "expected an interface name (e.g. 'can0') of at most 64 characters after the timestamp, found the end of "
            "the line");
  EXPECT_EQ(parseError("(1.0) 123#00"),
            "expected an interface name (e.g. 'can0') of at most 64 characters after the timestamp, found '123#00'");
  EXPECT_EQ(parseError("(1.0) can0"), "expected a frame '<id>#<data>', found the end of the line");
  EXPECT_EQ(parseError("(1.0) can0 12300"), "expected a frame '<id>#<data>', found '12300'");
  EXPECT_EQ(parseError("(1.0) can0 1234#00"),
            "expected a CAN id of 3 hex digits (11-bit) or 8 hex digits (29-bit) before '#', found '1234#00'");
  EXPECT_EQ(parseError("(1.0) can0 12G#00"), "expected a CAN id of 3 or 8 hex digits before '#', found '12G#00'");
  EXPECT_EQ(parseError("(1.0) can0 800#00"), "expected an 11-bit id (3 hex digits, at most 7FF), found '800#00'");
  EXPECT_EQ(parseError("(1.0) can0 40000000#00"),
            "expected a 29-bit id (8 hex digits, at most 1FFFFFFF), found '40000000#00'");
  EXPECT_EQ(parseError("(1.0) can0 20000004#0000080000000000"),
            "expected a data or remote frame, found the error frame '20000004#0000080000000000' (CAN_ERR_FLAG set; "
            "error frames, logged by candump -e, are not supported)");
  EXPECT_EQ(parseError("(1.0) can0 123#ABC"), "expected data (two hex digits per byte), found '123#ABC'");
  EXPECT_EQ(parseError("(1.0) can0 123#XY"), "expected data (two hex digits per byte), found '123#XY'");
  EXPECT_EQ(parseError("(1.0) can0 123#.11"), "expected data (two hex digits per byte), found '123#.11'");
  EXPECT_EQ(parseError("(1.0) can0 123#001122334455667788"),
            "expected data of at most 8 bytes, found '123#001122334455667788'");
  EXPECT_EQ(parseError("(1.0) can0 123#00_C"), "expected '_<raw DLC 9-F>' only after 8 data bytes, found '123#00_C'");
  EXPECT_EQ(parseError("(1.0) can0 123#0011223344556677_8"),
            "expected '_<raw DLC 9-F>' only after 8 data bytes, found '123#0011223344556677_8'");
  EXPECT_EQ(parseError("(1.0) can0 123#R9"),
            "expected 'R' alone or followed by one length digit 0-8 for a remote frame, found '123#R9'");
  EXPECT_EQ(parseError("(1.0) can0 123##"),
            "expected a CAN FD flags digit after '##' (0-3: 1 = BRS, 2 = ESI), found '123##'");
  EXPECT_EQ(parseError("(1.0) can0 123##400"),
            "expected a CAN FD flags digit after '##' (0-3: 1 = BRS, 2 = ESI), found '123##400'");
  EXPECT_EQ(parseError("(1.0) can0 123##0" + std::string(18, '0')),
            "expected CAN FD data of a valid length (0-8, 12, 16, 20, 24, 32, 48 or 64 bytes), found '123##0" +
                std::string(18, '0') + "'");
  EXPECT_EQ(parseError("(1.0) can0 123##0" + std::string(130, '0')),
            "expected CAN FD data of at most 64 bytes, found '123##0" + std::string(34, '0') + "...'");
  EXPECT_EQ(parseError("(1.0) can0 123###00"), "expected a CAN or CAN FD frame, found the CAN XL frame '123###00' (not supported)");
  EXPECT_EQ(parseError("(1.0) can0 123#00 X"), "expected the end of the line (or a direction 'R'/'T'), found 'X'");
  EXPECT_EQ(parseError("(1.0) can0 123#00 R extra"), "expected the end of the line, found 'extra'");
}

TEST(CandumpFile, LoadsTheFixtureLog) {
  const Result<std::vector<CandumpLine>> log = loadCandump(kCanData + "/drive.log");
  ASSERT_TRUE(log.has_value()) << log.error().message;
  // 8 lines: a comment and a blank line are skipped.
  ASSERT_EQ(log->size(), 6u);
  EXPECT_EQ((*log)[0].frame.id, 0x622u);
  EXPECT_EQ((*log)[2].frame.data[3], 0x28);  // LIGHT_STALK: low beam + front fog
  EXPECT_TRUE((*log)[3].frame.extended);
  EXPECT_EQ((*log)[3].frame.id, 0x18FEF121u);
  EXPECT_TRUE((*log)[4].frame.remote);
  EXPECT_TRUE((*log)[5].frame.fd);
  EXPECT_TRUE((*log)[5].frame.brs);
  EXPECT_EQ((*log)[5].frame.len, 12);
  EXPECT_NEAR((*log)[5].timestamp_s - (*log)[0].timestamp_s, 0.05, 1e-6);
}

TEST(CandumpFile, ErrorNamesFileAndLine) {
  const std::string path = kCanData + "/bad_data.log";
  const Result<std::vector<CandumpLine>> log = loadCandump(path);
  ASSERT_FALSE(log.has_value());
  EXPECT_EQ(log.error().message, path + ":4: expected data of at most 8 bytes, found '622#00000028000000000000'");
  const Result<std::vector<CandumpLine>> missing = loadCandump(kCanData + "/no_such.log");
  ASSERT_FALSE(missing.has_value());
  EXPECT_EQ(missing.error().message.rfind(kCanData + "/no_such.log: cannot open", 0), 0u);
}

// ---- candump's screen format (candump.hpp) -------------------------------------------------------

TEST(CandumpScreen, EveryFrameKind) {
  CandumpLine l = parseOk(" (1700000000.123456)  can0  123   [4]  DE AD BE EF");
  EXPECT_TRUE(l.timed);
  EXPECT_DOUBLE_EQ(l.timestamp_s, 1700000000.123456);
  EXPECT_DOUBLE_EQ(l.frame.timestamp_s, l.timestamp_s);
  EXPECT_EQ(l.interface, "can0");
  EXPECT_EQ(l.frame.id, 0x123u);
  EXPECT_FALSE(l.frame.extended);
  EXPECT_FALSE(l.frame.fd);
  ASSERT_EQ(l.frame.len, 4);
  EXPECT_EQ(l.frame.data[0], 0xDE);
  EXPECT_EQ(l.frame.data[3], 0xEF);
  EXPECT_EQ(l.frame.data[4], 0);

  l = parseOk("  vcan0  1F334455   [2]  00 11");  // no -t
  EXPECT_FALSE(l.timed);
  EXPECT_EQ(l.timestamp_s, 0.0);
  EXPECT_TRUE(l.frame.extended);
  EXPECT_EQ(l.frame.id, 0x1F334455u);
  EXPECT_EQ(l.frame.len, 2);
  EXPECT_EQ(l.frame.data[1], 0x11);

  l = parseOk("  can0  123   [4]  remote request");
  EXPECT_TRUE(l.frame.remote);
  EXPECT_EQ(l.frame.len, 4);
  EXPECT_EQ(l.frame.data[0], 0);

  l = parseOk("  can0  123   [0]");  // an empty data frame
  EXPECT_FALSE(l.frame.remote);
  EXPECT_EQ(l.frame.len, 0);

  // CAN FD: two length digits; with -x the flags.
  l = parseOk(" (0.250000)  can1  RX B E  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB");
  EXPECT_TRUE(l.frame.fd);
  EXPECT_TRUE(l.frame.brs);
  EXPECT_TRUE(l.frame.esi);
  ASSERT_EQ(l.frame.len, 12);
  EXPECT_EQ(l.frame.data[11], 0xBB);
  EXPECT_DOUBLE_EQ(l.timestamp_s, 0.25);
  l = parseOk("  can0  TX - -  123  [08]  01 02 03 04 05 06 07 08");
  EXPECT_TRUE(l.frame.fd);
  EXPECT_FALSE(l.frame.brs);
  EXPECT_EQ(l.frame.len, 8);
  l = parseOk("  can0  RX - -  123   [2]  01 02");  // -x on a classic frame
  EXPECT_FALSE(l.frame.fd);

  // -8: the raw DLC of a classic 8-byte frame.
  l = parseOk("  can0  123   {C}  00 11 22 33 44 55 66 77");
  EXPECT_EQ(l.frame.len, 8);
  EXPECT_EQ(l.frame.data[7], 0x77);

  // -a: the ASCII column, which may hold blanks and quotes, is ignored.
  l = parseOk("  can0  123   [4]  41 20 27 42         'A 'B'  ");
  EXPECT_EQ(l.frame.len, 4);
  EXPECT_EQ(l.frame.data[2], 0x27);

  // -t A: a date (read as UTC; only the gaps matter).
  l = parseOk(" (2023-11-14 22:13:20.250000)  can0  123   [1]  01");
  EXPECT_DOUBLE_EQ(l.timestamp_s, 1700000000.25);
  EXPECT_DOUBLE_EQ(parseOk(" (1970-01-01 00:00:00)  can0  123   [1]  01").timestamp_s, 0.0);
  EXPECT_DOUBLE_EQ(parseOk(" (2000-03-01 00:00:01.5)  can0  123   [1]  01").timestamp_s, 951868801.5);
}

TEST(CandumpScreen, EveryError) {
  EXPECT_EQ(parseError("  can0  123   [4]  DE AD"),
            "expected 4 data byte(s) as hex pairs after '[4]' (byte 3), found the end of the line");
  EXPECT_EQ(parseError("  can0  123   [2]  DE 0G"), "expected 2 data byte(s) as hex pairs after '[2]' (byte 2), found '0G'");
  EXPECT_EQ(parseError("  can0  123   [1]  11011110"),  // candump -B
            "expected 1 data byte(s) as hex pairs after '[1]' (byte 1), found '11011110'");
  EXPECT_EQ(parseError("  can0  123   [1]  DE AD"), "expected the end of the line after 1 data byte(s), found 'AD'");
  EXPECT_EQ(parseError("  can0  123   [9]  00"), "expected a classic frame's length 0-8, found '[9]'");
  EXPECT_EQ(parseError("  can0  123  [13]  00"),
            "expected a CAN FD length (0-8, 12, 16, 20, 24, 32, 48 or 64), found '[13]'");
  EXPECT_EQ(parseError("  can0  1234   [1]  00"),
            "expected a CAN id of 3 hex digits (11-bit) or 8 hex digits (29-bit) before the length '[n]', found '1234'");
  EXPECT_EQ(parseError("  can0  800   [1]  00"), "expected an 11-bit id (3 hex digits, at most 7FF), found '800'");
  EXPECT_EQ(parseError("  can0  20000080   [8]  00 00 00 00 00 00 00 00   ERRORFRAME"),
            "expected a data or remote frame, found the error frame '20000080' (CAN_ERR_FLAG set; error frames, "
            "logged by candump -e, are not supported)");
  EXPECT_EQ(parseError("  [1]  00"), "expected an interface name (e.g. 'can0') of at most 64 characters, found '[1]'");
  EXPECT_EQ(parseError("  can0  RX X -  123   [1]  00"), "expected the CAN FD flags 'B'/'-' and 'E'/'-' after RX, found 'X'");
  EXPECT_EQ(parseError(" (17x.0)  can0  123   [1]  00"), "expected a timestamp '(seconds.microseconds)', found '(17x.0)'");
  EXPECT_EQ(parseError(" (2023-13-14 22:13:20.25)  can0  123   [1]  00"),
            "expected a timestamp '(YYYY-MM-DD HH:MM:SS.ffffff)', found '(2023-13-14 22:13:20.25)'");
  EXPECT_EQ(parseError(" (2023-11-14 22:13:20,25)  can0  123   [1]  00"),
            "expected a timestamp '(YYYY-MM-DD HH:MM:SS.ffffff)', found '(2023-11-14 22:13:20,25)'");
  EXPECT_EQ(parseError(" (1.0  can0  123   [1]  00"),
            "expected a timestamp '(seconds.microseconds)' closed by ')', found '(1.0'");
  EXPECT_EQ(parseError("  can0  123   [2]  00 11   'x"), "expected the end of the line after 2 data byte(s), found ''x'");
}

TEST(CandumpFile, TheScreenCaptureOfTheFixtureGivesItsFrames) {
  const Result<std::vector<CandumpLine>> log = loadCandump(kCanData + "/drive.log");
  const Result<std::vector<CandumpLine>> screen = loadCandump(kCanData + "/drive_screen.log");
  ASSERT_TRUE(log.has_value()) << log.error().message;
  ASSERT_TRUE(screen.has_value()) << screen.error().message;
  ASSERT_EQ(screen->size(), log->size());
  for (std::size_t i = 0; i < log->size(); ++i) {
    const CandumpLine &a = (*log)[i], &b = (*screen)[i];
    EXPECT_EQ(b.timestamp_s, a.timestamp_s) << i;
    EXPECT_EQ(b.interface, a.interface) << i;
    EXPECT_EQ(b.frame.id, a.frame.id) << i;
    EXPECT_EQ(b.frame.extended, a.frame.extended) << i;
    EXPECT_EQ(b.frame.remote, a.frame.remote) << i;
    EXPECT_EQ(b.frame.fd, a.frame.fd) << i;
    EXPECT_EQ(b.frame.brs, a.frame.brs) << i;
    EXPECT_EQ(b.frame.esi, a.frame.esi) << i;
    EXPECT_EQ(b.frame.len, a.frame.len) << i;
    EXPECT_EQ(b.frame.data, a.frame.data) << i;
    EXPECT_EQ(b.frame.timestamp_s, a.frame.timestamp_s) << i;
  }
}

TEST(CandumpFile, ScreenLinesWithoutTimestampsTakeThePreviousLinesTime) {
  const std::filesystem::path path =
      std::filesystem::temp_directory_path() / ("fogbeam_screen_" + std::to_string(::getpid()) + ".log");
  {
    std::ofstream out(path);
    out << "  can0  123   [1]  01\n"
           " (5.000000)  can0  123   [1]  02\n"
           "  can0  123   [1]  03\n"
           "(6.000000) can0 123#04\n"
           "  can0  124   [1]  05\n";
  }
  const Result<std::vector<CandumpLine>> log = loadCandump(path.string());
  std::filesystem::remove(path);
  ASSERT_TRUE(log.has_value()) << log.error().message;
  ASSERT_EQ(log->size(), 5u);
  const double want[5] = {0.0, 5.0, 5.0, 6.0, 6.0};
  for (std::size_t i = 0; i < 5; ++i) {
    EXPECT_EQ((*log)[i].timestamp_s, want[i]) << i;
    EXPECT_EQ((*log)[i].frame.timestamp_s, want[i]) << i;
    EXPECT_EQ((*log)[i].frame.data[0], i + 1) << i;
  }
}

TEST(CandumpReplay, AsFastAsPossibleAndStopsWhenSinkSaysSo) {
  std::vector<CandumpLine> lines(5);
  for (std::size_t i = 0; i < lines.size(); ++i) lines[i].timestamp_s = 1000.0 + 100.0 * static_cast<double>(i);
  std::vector<double> seen;
  const auto start = std::chrono::steady_clock::now();
  replayCandump(lines, 0.0, [&](const CandumpLine& l) {
    seen.push_back(l.timestamp_s);
    return seen.size() < 3;
  });
  // 200 s of log at speed 0: immediate (no upper bound asserted, only that it did not pace).
  EXPECT_LT(std::chrono::steady_clock::now() - start, std::chrono::seconds(100));
  ASSERT_EQ(seen.size(), 3u);
  EXPECT_EQ(seen[2], 1200.0);
}

TEST(CandumpReplay, ReproducesScaledGaps) {
  // 0.2 s of log at speed 4 takes at least 50 ms; timing beyond that is not judged here.
  std::vector<CandumpLine> lines(3);
  lines[0].timestamp_s = 10.0;
  lines[1].timestamp_s = 10.1;
  lines[2].timestamp_s = 10.2;
  std::vector<std::chrono::steady_clock::time_point> at;
  const auto start = std::chrono::steady_clock::now();
  replayCandump(lines, 4.0, [&](const CandumpLine&) {
    at.push_back(std::chrono::steady_clock::now());
    return true;
  });
  ASSERT_EQ(at.size(), 3u);
  EXPECT_GE(at[1] - start, std::chrono::milliseconds(25));
  EXPECT_GE(at[2] - start, std::chrono::milliseconds(50));
  // A timestamp going backwards is sent at once; an empty log does nothing.
  lines[1].timestamp_s = 5.0;
  lines[2].timestamp_s = 10.0;
  const auto start2 = std::chrono::steady_clock::now();
  int n = 0;
  replayCandump(lines, 1.0, [&](const CandumpLine&) { return ++n > 0; });
  EXPECT_EQ(n, 3);
  EXPECT_LT(std::chrono::steady_clock::now() - start2, std::chrono::seconds(5));
  replayCandump({}, 1.0, [](const CandumpLine&) {
    ADD_FAILURE() << "sink called for an empty log";
    return true;
  });
}

TEST(CandumpErrors, RandomLinesNeverCrash) {
  // 20 000 lines from a fixed seed: half random bytes over candump's alphabet, half single-
  // character mutations of valid lines (-L and screen format). Parsing fails cleanly or yields
  // a consistent frame.
  const std::string alphabet = "()0123456789.abcdefABCDEF#R_ \tvcan0xXT-\x01\xff[]{}':";
  const std::vector<std::string> valid = {
      "(1700000000.123456) vcan0 123#DEADBEEF", "(1.0) can0 18FEF121#F6", "(1.0) can0 123##1112233",
      "(1.0) can0 123#R4", "(1.0) can0 123#0011223344556677_C", "(1.0) can0 123#11.22 T",
      // candump's screen format
      " (1.000000)  can0  123   [2]  DE AD   '..'", "  can0  RX B -  123  [12]  00 11 22 33 44 55 66 77 88 99 AA BB",
      "  can0  123   [4]  remote request", " (2023-11-14 22:13:20.250000)  can0  1F334455   {C}  00 11 22 33 44 55 66 77"};
  std::mt19937 rng(7);
  int accepted = 0;
  for (int trial = 0; trial < 20000; ++trial) {
    std::string line;
    if (trial % 2 == 0) {
      const std::size_t n = rng() % 60;
      for (std::size_t i = 0; i < n; ++i) line.push_back(alphabet[rng() % alphabet.size()]);
    } else {
      line = valid[rng() % valid.size()];
      const std::size_t edits = 1 + rng() % 3;
      for (std::size_t e = 0; e < edits && !line.empty(); ++e) {
        const std::size_t at = rng() % line.size();
        switch (rng() % 3) {
          case 0: line[at] = alphabet[rng() % alphabet.size()]; break;
          case 1: line.erase(at, 1); break;
          default: line.insert(at, 1, alphabet[rng() % alphabet.size()]); break;
        }
      }
    }
    const Result<CandumpLine> r = parseCandumpLine(line);
    if (!r) {
      EXPECT_EQ(r.error().message.rfind("expected ", 0), 0u) << r.error().message;
      continue;
    }
    ++accepted;
    const CanFrame& f = r->frame;
    EXPECT_LE(f.id, f.extended ? kCanMaxExtendedId : kCanMaxStandardId) << line;
    EXPECT_LE(f.len, f.fd ? kCanFdMaxLen : kCanMaxLen) << line;
    if (f.fd) {
      EXPECT_TRUE(isValidCanFdLength(f.len)) << line;
    }
    for (std::size_t i = f.remote ? 0 : f.len; i < f.data.size(); ++i) EXPECT_EQ(f.data[i], 0) << line;
  }
  EXPECT_GT(accepted, 100);
}

}  // namespace
}  // namespace fogbeam::ipc
