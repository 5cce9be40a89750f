# The rooms of fogbeam and what each may use (core/CMakeLists.txt, README "Layout"):
#
#   util  ←  physics  ←  scene  ←  render  ←  gl          ipc: util only
#
# Fails when a source or header of a room includes a fogbeam header of a room it may not use, when
# util, physics, scene or render include a GL, EGL, socket, CAN or shm header, or when a room's
# library links a fogbeam library of a room above it, or GL/EGL/sockets.
cmake_minimum_required(VERSION 3.25)  # IN_LIST in script mode
# Run by ctest (core_layering) with ROOT (the source tree) and LINKS
# ("room:lib,lib,…|room:…", each library's LINK_LIBRARIES); MIN_FILES (default 20) guards against
# a wrong ROOT that would check nothing.

# room → (folders, fogbeam include prefixes it may use)
set(rooms util physics scene render gl ipc)
set(util_dirs core/include/fogbeam/util core/src/util)
set(util_may util)
set(physics_dirs core/include/fogbeam/physics core/src/physics)
set(physics_may util physics)
set(scene_dirs core/include/fogbeam/scene core/src/scene)
set(scene_may util physics scene)
set(render_dirs core/include/fogbeam/render core/src/render)
set(render_may util physics scene render)
set(gl_dirs core/include/fogbeam/gl core/src/gl)
set(gl_may util physics scene render gl)
set(ipc_dirs ipc/include/fogbeam/ipc ipc/src ipc/examples)
set(ipc_may util ipc fogbeam_host.h)

# Headers no room below gl may include (and ipc may: it is the transport room).
set(os_or_gl
  "EGL/" "GL/" "GLES" "epoxy/" "GLFW/" "sys/socket\\.h" "netinet/" "arpa/inet\\.h"
  "linux/can" "sys/mman\\.h" "sys/shm\\.h" "mqueue\\.h")
set(pure_rooms util physics scene render)

set(bad "")
set(checked 0)
foreach(room IN LISTS rooms)
  foreach(dir IN LISTS ${room}_dirs)
    file(GLOB_RECURSE files "${ROOT}/${dir}/*.cpp" "${ROOT}/${dir}/*.hpp" "${ROOT}/${dir}/*.h" "${ROOT}/${dir}/*.c")
    foreach(f IN LISTS files)
      math(EXPR checked "${checked} + 1")
      file(STRINGS "${f}" lines REGEX "^[ \t]*#[ \t]*include")
      foreach(line IN LISTS lines)
        if(line MATCHES "<fogbeam/([A-Za-z0-9_.]+)")
          set(target "${CMAKE_MATCH_1}")
          if(NOT target IN_LIST ${room}_may)
            list(APPEND bad "${f}: ${line} (the ${room} room may use: ${${room}_may})")
          endif()
        endif()
        if(room IN_LIST pure_rooms)
          foreach(pat IN LISTS os_or_gl)
            if(line MATCHES "[<\"]${pat}")
              list(APPEND bad "${f}: ${line} (no GL/EGL/socket/CAN/shm header in the ${room} room)")
            endif()
          endforeach()
        endif()
      endforeach()
    endforeach()
  endforeach()
endforeach()

# Link interfaces: fogbeam_<room> may link only fogbeam libraries of the rooms it may use.
string(REPLACE "|" ";" entries "${LINKS}")
foreach(entry IN LISTS entries)
  string(FIND "${entry}" ":" colon)
  string(SUBSTRING "${entry}" 0 ${colon} room)
  math(EXPR from "${colon} + 1")
  string(SUBSTRING "${entry}" ${from} -1 libs)
  string(REPLACE "," ";" libs "${libs}")
  foreach(lib IN LISTS libs)
    if(lib MATCHES "^fogbeam_([a-z]+)$" AND NOT lib STREQUAL "fogbeam_warnings")
      if(NOT CMAKE_MATCH_1 IN_LIST ${room}_may)
        list(APPEND bad "fogbeam_${room} links ${lib} (the ${room} room may use: ${${room}_may})")
      endif()
    endif()
    if(room IN_LIST pure_rooms AND lib MATCHES "(^|[^a-z])(EGL|GL|OpenGL|epoxy|glfw|rt|socket)($|[^a-z])")
      list(APPEND bad "fogbeam_${room} links ${lib}")
    endif()
  endforeach()
endforeach()

if(NOT DEFINED MIN_FILES)
  set(MIN_FILES 20)
endif()
if(checked LESS MIN_FILES)
  message(FATAL_ERROR "core_layering: only ${checked} files found under ${ROOT}: wrong ROOT?")
endif()
if(bad)
  list(JOIN bad "\n  " msg)
  message(FATAL_ERROR "rooms used out of order:\n  ${msg}")
endif()
message(STATUS "core_layering: ${checked} files in ${rooms}: includes and link interfaces follow util ← physics ← scene ← render ← gl; ipc ← util")
