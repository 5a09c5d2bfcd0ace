# Writes the build-info header (cmake/recog_build_info.h.in) at build time, so that
# `--version` names the commit that was built, not the one CMake last configured. Run as
#   cmake -DSOURCE_DIR=... -DOUTPUT=... -DPROJECT_VERSION=... -DRECOG_BUILD_TYPE=... -P this-file
# configure_file rewrites OUTPUT only when its text changes, so an unchanged commit recompiles
# nothing.
set(RECOG_GIT_COMMIT unknown)
find_package(Git QUIET)
if(GIT_FOUND)
  execute_process(COMMAND ${GIT_EXECUTABLE} describe --always --dirty
                  WORKING_DIRECTORY ${SOURCE_DIR} OUTPUT_VARIABLE commit
                  RESULT_VARIABLE result OUTPUT_STRIP_TRAILING_WHITESPACE ERROR_QUIET)
  if(result EQUAL 0 AND commit)
    set(RECOG_GIT_COMMIT ${commit})
  endif()
endif()
configure_file(${SOURCE_DIR}/cmake/recog_build_info.h.in ${OUTPUT} @ONLY)
