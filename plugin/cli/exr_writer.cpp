#include "exr_writer.hpp"

#include <ImfChannelList.h>
#include <ImfFrameBuffer.h>
#include <ImfHeader.h>
#include <ImfOutputFile.h>

#include <exception>

namespace fogbeam::exr {

Status writeFrameLayers(const FrameLayers& l, const std::string& path) {
  try {
    Imf::Header header(l.width, l.height);
    Imf::FrameBuffer fb;
    const std::size_t px3 = 3 * sizeof(float), row3 = px3 * static_cast<std::size_t>(l.width);
    auto add3 = [&](const std::string& prefix, const std::vector<float>& buf) {
      const char* names[3] = {"R", "G", "B"};
      for (std::size_t c = 0; c < 3; ++c) {
        const std::string name = prefix.empty() ? names[c] : prefix + "." + names[c];
        header.channels().insert(name, Imf::Channel(Imf::FLOAT));
        // OpenEXR takes a non-const base pointer for both reading and writing.
        fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(buf.data() + c)), px3, row3));
      }
    };
    auto add1 = [&](const std::string& name, const std::vector<float>& buf) {
      header.channels().insert(name, Imf::Channel(Imf::FLOAT));
      fb.insert(name, Imf::Slice(Imf::FLOAT, reinterpret_cast<char*>(const_cast<float*>(buf.data())), sizeof(float),
                                 sizeof(float) * static_cast<std::size_t>(l.width)));
    };
    add3("", l.composite);
    add3("airlight", l.airlight);
    add3("surface", l.surface);
    add3("overlay", l.overlay);
    add1("transmittance.Y", l.transmittance);
    add1("distance.Z", l.distance);
    if (l.glow.size() == l.composite.size()) add3("glow", l.glow);
    if (l.glare.size() == l.composite.size()) add3("glare", l.glare);
    Imf::OutputFile file(path.c_str(), header);
    file.setFrameBuffer(fb);
    file.writePixels(l.height);
  } catch (const std::exception& e) {
    return Error{path + ": cannot write EXR (" + e.what() + ")"};
  }
  return Ok{};
}

}  // namespace fogbeam::exr
