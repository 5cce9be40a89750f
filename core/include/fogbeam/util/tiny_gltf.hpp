// fogbeam — tinygltf's declarations with the project's strict warnings silenced around them
// (the header is third-party code). The implementation is Debian's libtinygltf.so
// (TinyGLTF::TinyGLTF), so this declares only. Used by the GL pass's glTF import and by
// fogbeam_scenegen's writer.
#pragma once

#if defined(__GNUC__)
#pragma GCC diagnostic push
#pragma GCC diagnostic ignored "-Wconversion"
#pragma GCC diagnostic ignored "-Wsign-conversion"
#pragma GCC diagnostic ignored "-Wold-style-cast"
#pragma GCC diagnostic ignored "-Wshadow"
#pragma GCC diagnostic ignored "-Wdouble-promotion"
#pragma GCC diagnostic ignored "-Wpedantic"
#pragma GCC diagnostic ignored "-Wunused-parameter"
#endif
#include <tiny_gltf.h>  // IWYU pragma: export
#if defined(__GNUC__)
#pragma GCC diagnostic pop
#endif
