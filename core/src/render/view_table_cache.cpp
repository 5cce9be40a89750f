// fogbeam — vehicle lamps' view tables cached on disk (view_table_cache.hpp).
#include "render/view_table_cache.hpp"

#include "table_code_hash.hpp"

#include <fogbeam/util/overloaded.hpp>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <system_error>
#include <unistd.h>
#include <variant>
#include <vector>

namespace fogbeam::detail {

namespace {
// File layout, little-endian as the machine writes it (a cache is per machine): magic, the key
// (length, bytes), the guard (3 doubles), the table count, each table's header and arrays, and
// an FNV-1a checksum of everything before it.
constexpr char kMagic[8] = {'F', 'B', 'V', 'T', 'C', 'A', 'C', '1'};

std::uint64_t fnv1a(const char* p, std::size_t n, std::uint64_t h = 1469598103934665603ull) {
  for (std::size_t i = 0; i < n; ++i) {
    h ^= static_cast<unsigned char>(p[i]);
    h *= 1099511628211ull;
  }
  return h;
}


// Blobs (storeBytes: the fog light's annulus maps "am" and tables "fl"): the same layout with
// bytes as the body.
constexpr char kBlobMagic[8] = {'F', 'B', 'F', 'L', 'C', 'A', 'C', '1'};

// The kinds of cache file, each name's prefix ("<kind>-<hash>.bin"): view tables, the fog
// light's annulus maps and its tables. evictOldest counts these and only these, so storeBytes
// refuses any other kind (a file it would never trim).
constexpr std::array<std::string_view, 3> kKinds = {"vt", "am", "fl"};

bool knownKind(std::string_view kind) { return std::find(kKinds.begin(), kKinds.end(), kind) != kKinds.end(); }

std::filesystem::path fileFor(const std::filesystem::path& dir, const TableKey& key, std::string_view kind = "vt") {
  char name[48];
  std::snprintf(name, sizeof name, "%.*s-%016llx.bin", static_cast<int>(kind.size()), kind.data(),
                static_cast<unsigned long long>(key.hash()));
  return dir / name;
}

// The file's bytes with its checksum verified; `body` = their length less the checksum's.
bool readVerified(const std::filesystem::path& path, std::string& file, std::size_t& body) {
  std::ifstream in(path, std::ios::binary | std::ios::ate);
  if (!in) return false;
  const std::streamoff size = in.tellg();
  if (size <= 0) return false;
  file.assign(static_cast<std::size_t>(size), '\0');
  in.seekg(0);
  if (!in.read(file.data(), size)) return false;
  if (file.size() < sizeof kMagic + sizeof(std::uint64_t) * 2) return false;
  body = file.size() - sizeof(std::uint64_t);
  std::uint64_t sum = 0;
  std::memcpy(&sum, file.data() + body, sizeof sum);
  return sum == fnv1a(file.data(), body);
}

// The magic, the code version and key bytes, the near values (within TableKey::kTolerance).
bool readHeader(Reader& r, const char (&magicWanted)[8], const TableKey& key) {
  const char* magic = nullptr;
  if (!r.skip(sizeof magicWanted, magic) || std::memcmp(magic, magicWanted, sizeof magicWanted) != 0) return false;
  std::uint64_t keyLen = 0;
  const char* keyBytes = nullptr;
  const std::string code = FOGBEAM_TABLE_CODE_HASH;
  if (!r.get(keyLen) || keyLen != code.size() + key.bytes().size() || !r.skip(keyLen, keyBytes) ||
      std::memcmp(keyBytes, code.data(), code.size()) != 0 ||
      std::memcmp(keyBytes + code.size(), key.bytes().data(), key.bytes().size()) != 0)
    return false;
  std::uint64_t nearCount = 0;
  if (!r.get(nearCount) || nearCount != key.near().size()) return false;
  for (double want : key.near()) {
    double v = 0.0;
    if (!r.get(v) || !(std::abs(v - want) <= TableKey::kTolerance)) return false;
  }
  return true;
}

void writeHeader(Writer& w, const char (&magic)[8], const TableKey& key) {
  w.bytes(magic, sizeof magic);
  const std::string code = FOGBEAM_TABLE_CODE_HASH;
  w.put(static_cast<std::uint64_t>(code.size() + key.bytes().size()));
  w.bytes(code.data(), code.size());
  w.bytes(key.bytes().data(), key.bytes().size());
  w.put(static_cast<std::uint64_t>(key.near().size()));
  for (double v : key.near()) w.put(v);
}

// Appends the checksum and puts the file in place under `target` (in `dir`, created if need
// be): a name of its own per process and call, then an atomic rename; then trims `dir`.
Status writeInPlace(const std::filesystem::path& dir, const std::filesystem::path& target, Writer& w) {
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) return Error{dir.string() + ": cannot create the table cache directory: " + ec.message()};
  w.put(fnv1a(w.data().data(), w.data().size()));
  static std::atomic<unsigned> counter{0};
  std::filesystem::path tmp = target;
  tmp += ".tmp." + std::to_string(static_cast<long>(::getpid())) + "." + std::to_string(counter.fetch_add(1));
  {
    std::ofstream out(tmp, std::ios::binary | std::ios::trunc);
    out.write(w.data().data(), static_cast<std::streamsize>(w.data().size()));
    out.close();
    if (!out) {
      std::filesystem::remove(tmp, ec);
      return Error{tmp.string() + ": cannot write the table cache file"};
    }
  }
  std::filesystem::rename(tmp, target, ec);
  if (ec) {
    std::error_code ignored;
    std::filesystem::remove(tmp, ignored);
    return Error{target.string() + ": cannot rename the table cache file into place: " + ec.message()};
  }
  evictOldest(dir, target);
  return Ok{};
}
}  // namespace

TableKey& TableKey::add(double v) {
  char b[sizeof v];
  std::memcpy(b, &v, sizeof v);
  bytes_.append(b, sizeof b);
  return *this;
}

TableKey& TableKey::add(std::int64_t v) {
  char b[sizeof v];
  std::memcpy(b, &v, sizeof v);
  bytes_.append(b, sizeof b);
  return *this;
}

TableKey& TableKey::add(std::string_view s) {
  add(static_cast<std::int64_t>(s.size()));
  bytes_.append(s);
  return *this;
}

TableKey& TableKey::addProfile(const Profile& p) {
  std::visit(Overloaded{[&](const IsotropicProfile& m) { add("isotropic").add(m.intensity_cd); },
                        [&](const SpotProfile& m) { add("spot").add(m.peak_cd).add(m.inner).add(m.outer); },
                        [&](const TabulatedProfile& m) {
                          add("tabulated")
                              .add(static_cast<std::int64_t>(m.type))
                              .add(static_cast<std::int64_t>(m.symmetry));
                          for (const std::vector<double>* v : {&m.horizontal, &m.vertical, &m.candela}) {
                            add(static_cast<std::int64_t>(v->size()));
                            for (double x : *v) add(x);
                          }
                        }},
             p.model());
  return *this;
}

TableKey& TableKey::addPhase(const Phase& p) {
  std::visit(Overloaded{[&](const IsotropicPhase&) { add("isotropic"); },
                        [&](const HenyeyGreensteinPhase& m) { add("hg").add(m.g); },
                        [&](const FogMiePhase& m) {
                          add("fog-mie").add(m.diameter_um).add(m.g_hg).add(m.g_d).add(m.alpha).add(m.w);
                        }},
             p);
  return *this;
}

TableKey& TableKey::addNear(double v) {
  near_.push_back(v);
  return *this;
}

std::uint64_t TableKey::hash() const noexcept {
  std::uint64_t h = fnv1a(bytes_.data(), bytes_.size());
  for (double v : near_) {
    // Rounded to 1e-4: values within the tolerance share a name unless they straddle a step
    // (then a miss, a rebuild; never a wrong table: the load compares them within kTolerance).
    const auto q = static_cast<std::int64_t>(std::llround(v * 1e4));
    h = fnv1a(reinterpret_cast<const char*>(&q), sizeof q, h);
  }
  return h;
}

bool loadLampTables(const std::filesystem::path& dir, const TableKey& key, LampTables& out) {
  std::string file;
  std::size_t body = 0;
  if (!readVerified(fileFor(dir, key), file, body)) return false;
  Reader r(file.data(), body);
  if (!readHeader(r, kMagic, key)) return false;
  double guard[3];
  std::uint64_t count = 0;
  if (!r.get(guard[0]) || !r.get(guard[1]) || !r.get(guard[2]) || !r.get(count) || count != out.count) return false;
  // Into temporaries first: a damaged file must leave `out` as it was.
  std::vector<kernels::ViewTable> tables(out.count);
  constexpr std::size_t kMaxFloats = std::size_t{1} << 31;
  for (kernels::ViewTable& t : tables) {
    std::int32_t nA = 0, nB = 0, nX = 0;
    if (!r.get(t.a0) || !r.get(t.b0) || !r.get(t.invStep) || !r.get(nA) || !r.get(nB) || !r.get(nX) ||
        !r.get(t.distanceScale) || !r.get(t.weight) || !r.get(t.guardA) || !r.get(t.guardB) || !r.get(t.innerR2) ||
        !r.get(t.outerR2) || !r.array(t.data, kMaxFloats) || !r.array(t.skyQuads, kMaxFloats))
      return false;
    t.nA = nA;
    t.nB = nB;
    t.nX = nX;
    // An empty table (an inset of a lamp behind the eye) has no nodes; a full one exactly its grid's.
    const std::size_t nodes = static_cast<std::size_t>(std::max(nA, 0)) * static_cast<std::size_t>(std::max(nB, 0)) *
                              static_cast<std::size_t>(std::max(nX, 0)) * 2;
    if (!t.data.empty() && t.data.size() != nodes) return false;
  }
  if (r.at() != body) return false;
  for (std::size_t i = 0; i < out.count; ++i) out.tables[i] = std::move(tables[i]);
  for (int i = 0; i < 3; ++i) out.guard[i] = guard[i];
  return true;
}

Status storeLampTables(const std::filesystem::path& dir, const TableKey& key, const LampTables& in) {
  Writer w;
  writeHeader(w, kMagic, key);
  for (double g : in.guard) w.put(g);
  w.put(static_cast<std::uint64_t>(in.count));
  for (std::size_t i = 0; i < in.count; ++i) {
    const kernels::ViewTable& t = in.tables[i];
    w.put(t.a0);
    w.put(t.b0);
    w.put(t.invStep);
    w.put(static_cast<std::int32_t>(t.nA));
    w.put(static_cast<std::int32_t>(t.nB));
    w.put(static_cast<std::int32_t>(t.nX));
    w.put(t.distanceScale);
    w.put(t.weight);
    w.put(t.guardA);
    w.put(t.guardB);
    w.put(t.innerR2);
    w.put(t.outerR2);
    w.array(t.data);
    w.array(t.skyQuads);
  }
  return writeInPlace(dir, fileFor(dir, key), w);
}

namespace {
// The blob stored under `key`, read and verified into `file`; [data, data + n) its body.
bool loadBlob(const std::filesystem::path& dir, std::string_view kind, const TableKey& key, std::string& file,
              const char*& data, std::size_t& n) {
  std::size_t body = 0;
  if (!readVerified(fileFor(dir, key, kind), file, body)) return false;
  Reader r(file.data(), body);
  std::uint64_t count = 0;
  if (!readHeader(r, kBlobMagic, key) || !r.get(count) || count != body - r.at()) return false;
  n = static_cast<std::size_t>(count);
  return r.skip(n, data);
}
}  // namespace

bool loadBytes(const std::filesystem::path& dir, std::string_view kind, const TableKey& key, std::string& out) {
  std::string file;
  const char* data = nullptr;
  std::size_t n = 0;
  if (!loadBlob(dir, kind, key, file, data, n)) return false;  // a damaged file leaves `out` as it was
  out.assign(data, n);
  return true;
}

Status storeBytes(const std::filesystem::path& dir, std::string_view kind, const TableKey& key, std::string_view data) {
  if (!knownKind(kind))
    return Error{"table cache: unknown kind of file '" + std::string(kind) + "' (expected vt, am or fl)"};
  Writer w;
  writeHeader(w, kBlobMagic, key);
  w.put(static_cast<std::uint64_t>(data.size()));
  w.bytes(data.data(), data.size());
  return writeInPlace(dir, fileFor(dir, key, kind), w);
}

bool loadFloats(const std::filesystem::path& dir, std::string_view kind, const TableKey& key, std::vector<float>& out) {
  std::string file;
  const char* data = nullptr;
  std::size_t n = 0;
  if (!loadBlob(dir, kind, key, file, data, n) || n % sizeof(float) != 0) return false;
  out.resize(n / sizeof(float));
  std::memcpy(out.data(), data, n);
  return true;
}

Status storeFloats(const std::filesystem::path& dir, std::string_view kind, const TableKey& key,
                   const std::vector<float>& data) {
  return storeBytes(dir, kind, key,
                    std::string_view(reinterpret_cast<const char*>(data.data()), data.size() * sizeof(float)));
}

void evictOldest(const std::filesystem::path& dir, const std::filesystem::path& keep, std::uintmax_t maxBytes) {
  // Every distinct fog, rig or view stores its own files (a fog ramp visits many): keep the
  // newest within the budget. Errors (a file removed by another process meanwhile) are ignored.
  struct Entry {
    std::filesystem::file_time_type time;
    std::uintmax_t bytes;
    std::filesystem::path path;
  };
  std::vector<Entry> files;
  std::uintmax_t total = 0;
  std::error_code ec;
  for (std::filesystem::directory_iterator it(dir, ec), end; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    const std::size_t dash = name.find('-');
    if (dash == std::string::npos || !knownKind(std::string_view(name).substr(0, dash)) ||
        it->path().extension() != ".bin")
      continue;
    std::error_code e1, e2;
    const auto bytes = it->file_size(e1);
    const auto time = it->last_write_time(e2);
    if (e1 || e2) continue;
    files.push_back({time, bytes, it->path()});
    total += bytes;
  }
  if (total <= maxBytes) return;
  std::sort(files.begin(), files.end(), [](const Entry& a, const Entry& b) { return a.time < b.time; });
  for (const Entry& f : files) {
    if (total <= maxBytes) break;
    if (f.path == keep) continue;
    std::error_code e;
    if (std::filesystem::remove(f.path, e)) total -= f.bytes;
  }
}

}  // namespace fogbeam::detail
