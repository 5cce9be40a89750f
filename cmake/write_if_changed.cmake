# fogbeam_write_if_changed(<path> <text>): writes text to path unless the file already holds
# exactly that text, so that a generated source whose inputs did not change keeps its time stamp
# and rebuilds nothing. Included by the generator scripts run with cmake -P.
function(fogbeam_write_if_changed path text)
  if(EXISTS "${path}")
    file(READ "${path}" old)
    if(old STREQUAL text)
      return()
    endif()
  endif()
  file(WRITE "${path}" "${text}")
endfunction()
