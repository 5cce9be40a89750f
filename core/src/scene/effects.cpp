// fogbeam — the switchable additions beyond single scattering (effects.hpp).
#include <fogbeam/scene/effects.hpp>

namespace fogbeam {

std::string_view toString(AirlightDevice d) { return d == AirlightDevice::Gpu ? "gpu" : "cpu"; }

}  // namespace fogbeam
