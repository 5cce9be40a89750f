// A physics source that reaches up into the scene room and into sockets: core_layering_catches_violations
// runs tests/check_layering.cmake on this tree and expects it to fail naming both lines.
#include <fogbeam/scene/scene.hpp>
#include <sys/socket.h>
