// fogbeam — the switchable additions beyond single scattering (effects.hpp).
#include <fogbeam/scene/effects.hpp>

namespace fogbeam {

std::string_view toString(AirlightDevice d) { return d == AirlightDevice::Gpu ? "gpu" : "cpu"; }
std::string_view toString(GlowModel m) { return m == GlowModel::Apsf ? "apsf" : "table"; }

}  // namespace fogbeam
