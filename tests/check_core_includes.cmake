# Fails when a source of bvhopt::core, or any public header, includes a header of the file
# formats' libraries (assimp, stb, nlohmann-json), or when a library source runs a program
# (std::system, popen): those belong to bvhopt::io and the command-line program.
# cmake -DSOURCE_DIR=<project> "-DFOLDERS=scene;references;..." -P check_core_includes.cmake
set(globs ${SOURCE_DIR}/include/bvhopt/*.h)
foreach(folder ${FOLDERS})
  list(APPEND globs ${SOURCE_DIR}/src/${folder}/*.cpp ${SOURCE_DIR}/src/${folder}/*.h)
endforeach()
file(GLOB_RECURSE core_files ${globs})
file(GLOB library_files ${SOURCE_DIR}/src/*/*.cpp ${SOURCE_DIR}/src/*/*.h)
list(LENGTH core_files count)
if(count LESS 20)
  message(FATAL_ERROR "only ${count} core files found under ${SOURCE_DIR}: wrong SOURCE_DIR or FOLDERS?")
endif()

# Appends "file: what: line" to `bad` for every line of `files` that matches `regex`.
function(report_lines files regex what)
  foreach(file ${files})
    file(STRINGS ${file} lines REGEX "${regex}")
    foreach(line ${lines})
      list(APPEND bad "${file}: ${what}: ${line}")
    endforeach()
  endforeach()
  set(bad ${bad} PARENT_SCOPE)
endfunction()

set(bad)
report_lines("${core_files}" "^[ \t]*#[ \t]*include[ \t]*[<\"](assimp/|stb/|stb_|nlohmann/)" "file format library")
report_lines("${library_files}" "std::system[ \t]*\\(|[^a-z_]popen[ \t]*\\(" "runs a program")
if(bad)
  list(JOIN bad "\n" text)
  message(FATAL_ERROR "bvhopt::core must not depend on the file formats' libraries, and no library may run programs:\n${text}")
endif()
message(STATUS "${count} core files checked")
