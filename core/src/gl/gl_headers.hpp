// fogbeam — the one header that includes OpenGL and EGL (Filament's gl_headers.h does the same).
// Every GL/EGL entry point goes through libepoxy, which loads libEGL / libGL at run time, so the
// surface pass links no GL library directly and can report "no EGL" instead of failing to load.
// Private to fogbeam_gl: never include it from a public header.
#pragma once

#include <epoxy/egl.h>  // IWYU pragma: export
#include <epoxy/gl.h>   // IWYU pragma: export
