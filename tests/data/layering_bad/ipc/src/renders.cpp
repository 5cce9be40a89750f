// ipc may use util only.
#include <fogbeam/render/frame.hpp>
