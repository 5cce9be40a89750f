// The documents are the contract with integrators (docs/shm.md for image generators, docs/protocol.md
// for simulator hosts): every offset row of their layout tables, and the sizes in their headings,
// must equal the code's constants (shm_layout.h, protocol.hpp's wire:: offsets). The code's side is
// also pinned at compile time (ipc/src/shm_layout.cpp, protocol.cpp); this test reads the documents
// themselves, so neither side can drift from the other.
//
// Rows are compared in order: the k-th row of a table must state the offset and type of the k-th
// field expected here, and its field text must name that field. A row added to or removed from a
// table, or a table that cannot be found, fails too.
#include <fogbeam/ipc/protocol.hpp>
#include <fogbeam/ipc/shm_layout.h>
#include <fogbeam/util/files.hpp>

#include <gtest/gtest.h>

#include <algorithm>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <sstream>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

namespace fogbeam::ipc {
namespace {

const std::string kDocs = std::string(FOGBEAM_CONFIG_DIR) + "/../docs/";

// One row of a Markdown layout table: its first three cells and where it is.
struct Row {
  std::string offset, type, field;
  std::size_t line = 0;  // 1-based, for messages
};

std::string trim(std::string_view s) {
  const auto b = s.find_first_not_of(" \t");
  if (b == std::string_view::npos) return {};
  const auto e = s.find_last_not_of(" \t");
  return std::string(s.substr(b, e - b + 1));
}

// The cells of a table line "| a | b | c |"; an escaped "\|" stays inside its cell.
std::vector<std::string> cells(const std::string& line) {
  std::vector<std::string> out;
  std::string cur;
  for (std::size_t i = 1; i < line.size(); ++i) {  // skip the leading '|'
    if (line[i] == '\\' && i + 1 < line.size() && line[i + 1] == '|') {
      cur += '|';
      ++i;
    } else if (line[i] == '|') {
      out.push_back(trim(cur));
      cur.clear();
    } else {
      cur += line[i];
    }
  }
  return out;
}

struct Doc {
  std::string path;
  std::vector<std::string> lines;

  explicit Doc(const std::string& name) : path(kDocs + name) {
    const auto text = readTextFile(path);
    EXPECT_TRUE(text) << text.error().message;
    if (!text) return;
    std::istringstream in(*text);
    for (std::string l; std::getline(in, l);) lines.push_back(l);
  }

  // The index of the first line that starts with `title` (a heading or a caption); lines.size()
  // when there is none.
  std::size_t find(std::string_view title) const {
    for (std::size_t i = 0; i < lines.size(); ++i)
      if (std::string_view(lines[i]).substr(0, title.size()) == title) return i;
    return lines.size();
  }

  // The body rows of the first table after the line `title` starts, before the next heading.
  std::vector<Row> table(std::string_view title) const {
    std::vector<Row> rows;
    std::size_t i = find(title);
    if (i == lines.size()) {
      ADD_FAILURE() << path << ": no line starting with \"" << title << "\"";
      return rows;
    }
    for (++i; i < lines.size() && lines[i].rfind('|', 0) != 0; ++i)
      if (lines[i].rfind("#", 0) == 0) break;
    if (i + 1 >= lines.size() || lines[i].rfind('|', 0) != 0) {
      ADD_FAILURE() << path << ": no table after \"" << title << "\"";
      return rows;
    }
    for (i += 2; i < lines.size() && lines[i].rfind('|', 0) == 0; ++i) {  // past header and |---|
      const auto c = cells(lines[i]);
      if (c.size() < 3) {
        ADD_FAILURE() << path << ":" << i + 1 << ": a row with fewer than 3 cells";
        continue;
      }
      rows.push_back({c[0], c[1], c[2], i + 1});
    }
    return rows;
  }
};

// What the code says about one row: the offset (as the document writes it), the type, a word the
// field's text must contain, and the constant's name for the message.
struct Field {
  std::string offset;
  std::string type;
  std::string word;
  std::string constant;
};

#define FIELD(value, type, word) Field{std::to_string(value), type, word, #value}

void expectTable(const Doc& doc, std::string_view title, const std::vector<Field>& fields) {
  const std::vector<Row> rows = doc.table(title);
  EXPECT_EQ(rows.size(), fields.size()) << doc.path << ", table \"" << title << "\": " << rows.size()
                                        << " rows, the code has " << fields.size() << " fields";
  for (std::size_t k = 0; k < std::min(rows.size(), fields.size()); ++k) {
    const Row& r = rows[k];
    const Field& f = fields[k];
    const std::string where = doc.path + ":" + std::to_string(r.line) + " (\"" + std::string(title) + "\", row " +
                              std::to_string(k + 1) + ", " + f.constant + "): ";
    EXPECT_EQ(r.offset, f.offset) << where << "the document states offset " << r.offset << ", the code has "
                                  << f.offset;
    EXPECT_EQ(r.type, f.type) << where << "type";
    EXPECT_NE(r.field.find(f.word), std::string::npos)
        << where << "the field \"" << r.field << "\" does not name \"" << f.word << "\"";
  }
}

// A heading's or caption's whole line must read `expected` (the sizes and codes it states).
void expectLine(const Doc& doc, std::string_view start, const std::string& expected) {
  const std::size_t i = doc.find(start);
  ASSERT_LT(i, doc.lines.size()) << doc.path << ": no line starting with \"" << start << "\"";
  EXPECT_EQ(doc.lines[i], expected) << doc.path << ":" << i + 1;
}

std::string n(std::size_t v) { return std::to_string(v); }

TEST(LayoutDocs, ShmTablesEqualShmLayoutH) {
  const Doc doc("shm.md");
  ASSERT_FALSE(doc.lines.empty());
  expectLine(doc, "## Header (", "## Header (" + n(FOGBEAM_SHM_HEADER_SIZE) + " bytes)");
  expectLine(doc, "## Slot metadata (",
             "## Slot metadata (" + n(FOGBEAM_SHM_SLOT_META_SIZE) + " bytes at the start of each slot)");
  expectTable(doc, "## Header (",
              {
                  FIELD(FOGBEAM_HDR_MAGIC, "u32", "magic"),
                  FIELD(FOGBEAM_HDR_VERSION, "u16", "version = " + n(FOGBEAM_SHM_VERSION)),
                  FIELD(FOGBEAM_HDR_HEADER_SIZE, "u16", "header size = " + n(FOGBEAM_SHM_HEADER_SIZE)),
                  FIELD(FOGBEAM_HDR_SLOT_COUNT, "u32", "slot count"),
                  FIELD(FOGBEAM_HDR_FORMAT, "u32", "pixel format"),
                  FIELD(FOGBEAM_HDR_WIDTH, "u32", "width"),
                  FIELD(FOGBEAM_HDR_HEIGHT, "u32", "height"),
                  FIELD(FOGBEAM_HDR_BYTES_PER_PIXEL, "u32", "bytes per pixel"),
                  FIELD(FOGBEAM_HDR_HAS_DISTANCE, "u32", "distance plane"),
                  FIELD(FOGBEAM_HDR_FIRST_SLOT, "u64", "offset of slot 0 (= " + n(FOGBEAM_SHM_HEADER_SIZE) + ")"),
                  FIELD(FOGBEAM_HDR_SLOT_STRIDE, "u64", "slot stride"),
                  FIELD(FOGBEAM_HDR_PIXELS_OFFSET, "u64",
                        "offset of the pixels inside a slot (= " + n(FOGBEAM_SHM_SLOT_META_SIZE) + ")"),
                  FIELD(FOGBEAM_HDR_PIXELS_BYTES, "u64", "pixel bytes"),
                  FIELD(FOGBEAM_HDR_DISTANCE_OFFSET, "u64", "offset of the distance plane"),
                  FIELD(FOGBEAM_HDR_SEGMENT_BYTES, "u64", "segment size"),
                  FIELD(FOGBEAM_HDR_GENERATION, "u64", "generation"),
                  FIELD(FOGBEAM_HDR_WRITER_PID, "u32", "writer pid"),
                  FIELD(FOGBEAM_HDR_WRITER_STATE, "u32 (atomic)",
                        "writer state: " + n(FOGBEAM_WRITER_RUNNING) + " running, " + n(FOGBEAM_WRITER_CLOSED) +
                            " closed"),
                  FIELD(FOGBEAM_HDR_HEARTBEAT_NS, "u64 (atomic)", "heartbeat"),
                  FIELD(FOGBEAM_HDR_LATEST, "u64 (atomic)", "latest: (frame number << 8) | slot index"),
                  FIELD(FOGBEAM_HDR_CHANNEL_NAME, "char[64]", "channel name"),
              });
  // The magic as the document spells it, and the format codes.
  const std::vector<Row> header = doc.table("## Header (");
  ASSERT_GE(header.size(), 5u);
  char magic[16];
  std::snprintf(magic, sizeof magic, "`0x%08X`", FOGBEAM_SHM_MAGIC);
  EXPECT_NE(header[0].field.find(magic), std::string::npos) << header[0].field;
  for (const auto& [code, name] : {std::pair{FOGBEAM_FORMAT_RGBA8_SRGB, " RGBA8 sRGB"},
                                   std::pair{FOGBEAM_FORMAT_RGBA16F_LINEAR, " RGBA16F linear"},
                                   std::pair{FOGBEAM_FORMAT_RGBA16F_OVERLAY, " RGBA16F overlay"},
                                   std::pair{FOGBEAM_FORMAT_DISTANCE_F32, " f32 distance"}})
    EXPECT_NE(header[4].field.find(n(code) + name), std::string::npos) << header[4].field;

  expectTable(doc, "## Slot metadata (",
              {
                  FIELD(FOGBEAM_SLOT_SEQ, "u64 (atomic)", "seqlock counter"),
                  FIELD(FOGBEAM_SLOT_FRAME, "u64", "frame number"),
                  FIELD(FOGBEAM_SLOT_SIM_TIME, "f64", "simulation time"),
                  FIELD(FOGBEAM_SLOT_POSE, "f64 ×3", "eye position"),
                  FIELD(FOGBEAM_SLOT_ORIENTATION, "f32 ×3", "yaw, pitch, roll"),
                  FIELD(FOGBEAM_SLOT_LIGHTS, "u32", "light bits"),
                  FIELD(FOGBEAM_SLOT_EGO_SEQ, "u32", "ego-state message"),
                  FIELD(FOGBEAM_SLOT_LAMP_SEQ, "u32", "lamp-state message"),
                  FIELD(FOGBEAM_SLOT_ENV_SEQ, "u32", "environment message"),
                  FIELD(FOGBEAM_SLOT_TRAFFIC_COUNT, "u32", "traffic objects"),
                  FIELD(FOGBEAM_SLOT_SURFACE_MS, "f64", "surface pass (ms)"),
                  FIELD(FOGBEAM_SLOT_AIRLIGHT_MS, "f64", "airlight (ms)"),
                  FIELD(FOGBEAM_SLOT_COMPOSITE_MS, "f64", "composite (ms)"),
                  FIELD(FOGBEAM_SLOT_TOTAL_MS, "f64", "total render time (ms)"),
                  FIELD(FOGBEAM_SLOT_LATENCY_MS, "f64", "latency (ms)"),
                  FIELD(FOGBEAM_SLOT_PUBLISH_NS, "u64", "publish time"),
                  FIELD(FOGBEAM_SLOT_FRAME_REQUEST, "u64", "frame request"),
                  FIELD(FOGBEAM_SLOT_FOV_X, "f32", "horizontal field of view"),
                  FIELD(FOGBEAM_SLOT_FOV_Y, "f32", "vertical field of view"),
                  FIELD(FOGBEAM_SLOT_FRUSTUM, "f32 ×4", "off-axis frustum"),
                  FIELD(FOGBEAM_SLOT_HOST_FRAME, "u64", "host frame"),
              });
}

TEST(LayoutDocs, ProtocolTablesEqualTheCodec) {
  using namespace wire;
  const Doc doc("protocol.md");
  ASSERT_FALSE(doc.lines.empty());
  auto type = [](MessageType t) { return n(static_cast<std::size_t>(t)); };
  // Headings: each message's type code and payload size.
  expectLine(doc, "## Header (", "## Header (" + n(kHeaderSize) + " bytes, every message)");
  expectLine(doc, "## Ego state (",
             "## Ego state (type " + type(MessageType::EgoState) + ", " + n(kEgoStateSize) + " bytes)");
  expectLine(doc, "## Lamp state (",
             "## Lamp state (type " + type(MessageType::LampState) + ", " + n(kLampStateSize) +
                 " bytes): the ego vehicle's lights");
  expectLine(doc, "## Traffic list (",
             "## Traffic list (type " + type(MessageType::TrafficList) + ", " + n(kTrafficHeaderSize) + " + " +
                 n(kTrafficObjectSize) + "·n bytes)");
  expectLine(doc, "Object (", "Object (" + n(kTrafficObjectSize) + " bytes):");
  expectLine(doc, "## Environment (",
             "## Environment (type " + type(MessageType::Environment) + ", " + n(kEnvironmentSize) + " bytes)");
  expectLine(doc, "## Frame request (",
             "## Frame request (type " + type(MessageType::FrameRequest) + ", " + n(kFrameRequestSize) +
                 " bytes): lock-step mode");

  expectTable(doc, "## Header (",
              {
                  FIELD(kHeaderMagic, "u32", "magic"),
                  FIELD(kHeaderVersion, "u16", "version"),
                  FIELD(kHeaderType, "u16", "type"),
                  FIELD(kHeaderPayloadLength, "u32", "payload_length"),
                  FIELD(kHeaderSequence, "u32", "sequence"),
                  FIELD(kHeaderSimTime, "f64", "sim_time_s"),
              });
  const std::vector<Row> header = doc.table("## Header (");
  ASSERT_EQ(header.size(), 6u);
  char magic[16];
  std::snprintf(magic, sizeof magic, "`0x%08X`", kProtocolMagic);
  EXPECT_NE(doc.lines[header[0].line - 1].find(magic), std::string::npos) << doc.lines[header[0].line - 1];
  EXPECT_NE(doc.lines[header[1].line - 1].find("| " + n(kProtocolVersion) + " |"), std::string::npos);
  EXPECT_NE(doc.lines[header[3].line - 1].find("datagram size − " + n(kHeaderSize)), std::string::npos);

  expectTable(doc, "## Ego state (",
              {
                  FIELD(kEgoPose + kPoseX, "f64", "x (m)"),
                  FIELD(kEgoPose + kPoseY, "f64", "y (m)"),
                  FIELD(kEgoPose + kPoseZ, "f64", "z (m)"),
                  FIELD(kEgoPose + kPoseYaw, "f32", "yaw (deg)"),
                  FIELD(kEgoPose + kPosePitch, "f32", "pitch (deg)"),
                  FIELD(kEgoPose + kPoseRoll, "f32", "roll (deg)"),
                  FIELD(kEgoSpeed, "f32", "speed (m/s)"),
              });
  expectTable(doc, "## Lamp state (",
              {
                  FIELD(kLampLights, "u32", "lights"),
                  FIELD(kLampBending, "f32", "bending (deg)"),
                  FIELD(kLampReserved, "u32", "reserved"),
              });
  // The traffic list's third row is the object array: "4 + 48 k".
  expectTable(doc, "## Traffic list (",
              {
                  FIELD(kTrafficCount, "u16", "count n"),
                  FIELD(kTrafficFlags, "u16", "flags"),
                  Field{n(kTrafficObjects) + " + " + n(kTrafficObjectSize) + " k", "", "object k",
                        "kTrafficObjects + kTrafficObjectSize k"},
              });
  const std::vector<Row> traffic = doc.table("## Traffic list (");
  ASSERT_GE(traffic.size(), 1u);
  EXPECT_NE(doc.lines[traffic[0].line - 1].find("≤ " + n(kMaxTrafficPerDatagram)), std::string::npos);
  expectTable(doc, "Object (",
              {
                  FIELD(kObjectId, "u32", "id"),
                  FIELD(kObjectVehicleClass, "u16", "vehicle class"),
                  FIELD(kObjectFlags, "u16", "flags"),
                  FIELD(kObjectPose + kPoseX, "f64 ×3", "x, y, z (m)"),
                  FIELD(kObjectPose + kPoseYaw, "f32 ×3", "yaw, pitch, roll (deg)"),
                  FIELD(kObjectLights, "u32", "lights"),
              });
  expectTable(doc, "## Environment (",
              {
                  FIELD(kEnvVisibility, "f32", "visibility"),
                  FIELD(kEnvExtinction, "f32", "extinction"),
                  FIELD(kEnvAlbedo, "f32", "albedo"),
                  FIELD(kEnvPhase, "u8", "phase function"),
                  FIELD(kEnvReserved, "u8 ×3", "reserved"),
                  FIELD(kEnvG, "f32", "g (Henyey–Greenstein)"),
                  FIELD(kEnvDropletDiameter, "f32", "droplet diameter"),
                  FIELD(kEnvAmbient, "f32", "ambient luminance"),
              });
  expectTable(doc, "## Frame request (", {FIELD(kFrameNumber, "u64", "frame number")});

  // Transport: the largest datagram.
  EXPECT_LT(doc.find("* UDP over IPv4, one message per datagram, at most 65 507 bytes."), doc.lines.size());
  EXPECT_EQ(kMaxDatagram, 65507u);
}

// The light bits table: the bit each light has in protocol.hpp's light:: namespace.
TEST(LayoutDocs, ProtocolLightBitsEqualTheCodec) {
  const Doc doc("protocol.md");
  const std::vector<Row> rows = [&] {
    // Two-column table: read it with an empty third cell.
    std::vector<Row> out;
    std::size_t i = doc.find("| bit | light |");
    EXPECT_LT(i, doc.lines.size()) << doc.path << ": no light bits table";
    for (i += 2; i < doc.lines.size() && doc.lines[i].rfind('|', 0) == 0; ++i) {
      const auto c = cells(doc.lines[i]);
      if (c.size() >= 2) out.push_back({c[0], c[1], "", i + 1});
    }
    return out;
  }();
  auto hex = [](std::uint32_t v) {  // as the document writes them: "0x020"
    char b[16];
    std::snprintf(b, sizeof b, "0x%03X", v);
    return std::string(b);
  };
  const std::vector<std::pair<std::uint32_t, std::string>> bits = {
      {light::kPosition, "position (park)"}, {light::kLowBeam, "low beam"},       {light::kHighBeam, "high beam"},
      {light::kBrake, "brake"},              {light::kIndicatorLeft, "indicator left"},
      {light::kIndicatorRight, "indicator right"}, {light::kFrontFog, "front fog"}, {light::kRearFog, "rear fog"},
      {light::kDrl, "daytime running lights"}};
  ASSERT_EQ(rows.size(), bits.size());
  for (std::size_t k = 0; k < bits.size(); ++k) {
    EXPECT_EQ(rows[k].offset, hex(bits[k].first)) << doc.path << ":" << rows[k].line << " (" << bits[k].second << ")";
    EXPECT_EQ(rows[k].type, bits[k].second) << doc.path << ":" << rows[k].line;
  }
}

#undef FIELD

}  // namespace
}  // namespace fogbeam::ipc
