# CMake helpers of the iceskate C++ packages: loaded by find_package(iceskate_native) (ament's
# CONFIG_EXTRAS) in the controller packages, and included by iceskate_native's own CMakeLists.

# This file's directory: the generator of the controller packages' parameter headers lies beside
# it (the source tree's cmake/, or share/iceskate_native/cmake once installed).
set(ICESKATE_NATIVE_CMAKE_DIR "${CMAKE_CURRENT_LIST_DIR}")

# Release by default (-O3 -DNDEBUG), C++17 without compiler extensions.
macro(iceskate_cxx_defaults)
  if(NOT CMAKE_BUILD_TYPE AND NOT CMAKE_CONFIGURATION_TYPES)
    set(CMAKE_BUILD_TYPE Release CACHE STRING "Build type (default Release: -O3 -DNDEBUG)" FORCE)
  endif()
  set(CMAKE_CXX_STANDARD 17)
  set(CMAKE_CXX_STANDARD_REQUIRED ON)
  set(CMAKE_CXX_EXTENSIONS OFF)
endmacro()

# The Python 3.11 interpreter and module development files, and nanobind's CMake package from
# that interpreter's nanobind wheel.
macro(iceskate_find_nanobind)
  find_package(Python 3.11 REQUIRED COMPONENTS Interpreter Development.Module)
  execute_process(
    COMMAND "${Python_EXECUTABLE}" -m nanobind --cmake_dir
    OUTPUT_VARIABLE nanobind_ROOT OUTPUT_STRIP_TRAILING_WHITESPACE
    COMMAND_ERROR_IS_FATAL ANY)
  find_package(nanobind CONFIG REQUIRED)
endmacro()

# nanobind's core as one shared library, lib/libiceskate_nanobind.so of iceskate_native's install:
# compiled once for the kernel and every controller module (a static copy per module would be
# compiled once per package). ICESKATE_NANOBIND_CORE is the target nanobind_add_module(...
# NB_SHARED PROTECT_STACK) builds its core as, or links if it exists. PROTECT_STACK leaves the
# compiler's default stack protection (nanobind would set -fno-stack-protector on the core too,
# which an imported library cannot take).
set(ICESKATE_NANOBIND_CORE nanobind-ps)
set(ICESKATE_NANOBIND_NAME iceskate_nanobind)
macro(iceskate_nanobind_library)
  set_target_properties(${ICESKATE_NANOBIND_CORE} PROPERTIES
    OUTPUT_NAME ${ICESKATE_NANOBIND_NAME}
    INTERPROCEDURAL_OPTIMIZATION_RELEASE OFF)  # a link-time pass would cost more than it saves
endmacro()

# In a controller package: iceskate_native's installed core as the target nanobind_add_module
# links instead of building its own.
macro(iceskate_import_nanobind_library)
  if(NOT TARGET ${ICESKATE_NANOBIND_CORE})
    get_filename_component(_nanobind_prefix "${iceskate_native_DIR}/../../.." ABSOLUTE)
    set(_nanobind_file ${CMAKE_SHARED_LIBRARY_PREFIX}${ICESKATE_NANOBIND_NAME})
    set(_nanobind_library "${_nanobind_prefix}/lib/${_nanobind_file}${CMAKE_SHARED_LIBRARY_SUFFIX}")
    if(NOT EXISTS "${_nanobind_library}")
      message(FATAL_ERROR "iceskate_native's nanobind core is not at ${_nanobind_library}: "
                          "build iceskate_native first")
    endif()
    add_library(${ICESKATE_NANOBIND_CORE} SHARED IMPORTED)
    set_target_properties(${ICESKATE_NANOBIND_CORE} PROPERTIES
      IMPORTED_LOCATION "${_nanobind_library}"
      INTERFACE_COMPILE_DEFINITIONS NB_SHARED
      INTERFACE_INCLUDE_DIRECTORIES "${Python_INCLUDE_DIRS};${NB_DIR}/include"
      INTERFACE_COMPILE_FEATURES cxx_std_17)
  endif()
endmacro()

# A controller package (after project() and find_package(iceskate_native)):
#   <project>_law   static library of SOURCES against iceskate_native's Eigen-only headers and
#                   include/ (no Pinocchio), warnings are errors
#   PARAMETERS      the Python module of its parameter dataclasses (e.g. <project>/parameters.py):
#                   generate_parameters.py writes <project>/parameters.hpp (the structs) and
#                   <project>/parameter_readers.hpp (their by-name readers, for bindings.cpp)
#                   from it into the build tree's include path, again whenever it changes
#   _law            nanobind module <project>._law from src/bindings.cpp (-O3, not -Os), linking
#                   iceskate_native's nanobind core (lib/libiceskate_nanobind.so)
# and installs the Python package <project>/, config/, and the executable lib/<project>/<project>
# (`ros2 run <project> <project>`) that runs <project>.<project>_node:main with this interpreter.
macro(iceskate_controller_package)
  cmake_parse_arguments(_controller "" "PARAMETERS" "SOURCES" ${ARGN})
  iceskate_cxx_defaults()
  find_package(ament_cmake_python REQUIRED)
  find_package(Eigen3 REQUIRED NO_MODULE)
  iceskate_find_nanobind()
  set(_controller_warnings -Wall -Wextra -Wpedantic -Werror)

  set(_controller_generated "${CMAKE_CURRENT_BINARY_DIR}/generated/include")
  set(_controller_headers)
  if(_controller_PARAMETERS)
    string(REGEX REPLACE "\\.py$" "" _controller_module "${_controller_PARAMETERS}")
    string(REPLACE "/" "." _controller_module "${_controller_module}")
    set(_controller_headers
      "${_controller_generated}/${PROJECT_NAME}/parameters.hpp"
      "${_controller_generated}/${PROJECT_NAME}/parameter_readers.hpp")
    add_custom_command(
      OUTPUT ${_controller_headers}
      COMMAND "${Python_EXECUTABLE}" "${ICESKATE_NATIVE_CMAKE_DIR}/generate_parameters.py"
              --path "${CMAKE_CURRENT_SOURCE_DIR}" --module "${_controller_module}"
              --namespace "${PROJECT_NAME}" --out "${_controller_generated}/${PROJECT_NAME}"
              --depfile "${CMAKE_CURRENT_BINARY_DIR}/generated/parameters.d"
      DEPENDS "${CMAKE_CURRENT_SOURCE_DIR}/${_controller_PARAMETERS}"
              "${ICESKATE_NATIVE_CMAKE_DIR}/generate_parameters.py"
      # every Python module the generator imported (iceskate_sim's schema among them)
      DEPFILE "${CMAKE_CURRENT_BINARY_DIR}/generated/parameters.d"
      COMMENT "Generating the C++ parameter structs of ${_controller_PARAMETERS}"
      VERBATIM)
  endif()

  add_library(${PROJECT_NAME}_law STATIC ${_controller_SOURCES} ${_controller_headers})
  target_include_directories(${PROJECT_NAME}_law PUBLIC
    "$<BUILD_INTERFACE:${CMAKE_CURRENT_SOURCE_DIR}/include>"
    "$<BUILD_INTERFACE:${_controller_generated}>" ${iceskate_native_INCLUDE_DIRS})
  target_link_libraries(${PROJECT_NAME}_law PUBLIC Eigen3::Eigen)
  target_compile_options(${PROJECT_NAME}_law PRIVATE ${_controller_warnings})
  set_target_properties(${PROJECT_NAME}_law PROPERTIES
    POSITION_INDEPENDENT_CODE ON CXX_VISIBILITY_PRESET hidden VISIBILITY_INLINES_HIDDEN ON)

  iceskate_import_nanobind_library()
  # NOSTRIP: named in profiles; NB_SHARED PROTECT_STACK: link iceskate_native's nanobind core
  nanobind_add_module(_law NB_SHARED NOMINSIZE NOSTRIP PROTECT_STACK src/bindings.cpp)
  target_link_libraries(_law PRIVATE ${PROJECT_NAME}_law)
  target_compile_options(_law PRIVATE ${_controller_warnings})
  # nanobind's core from iceskate_native's lib/ (its build-tree RPATH already names it)
  set_target_properties(_law PROPERTIES INSTALL_RPATH_USE_LINK_PATH TRUE)

  ament_python_install_package(${PROJECT_NAME})
  install(TARGETS _law LIBRARY DESTINATION "${PYTHON_INSTALL_DIR}/${PROJECT_NAME}")
  install(DIRECTORY config DESTINATION share/${PROJECT_NAME})
  set(_controller_script "${CMAKE_CURRENT_BINARY_DIR}/scripts/${PROJECT_NAME}")
  file(GENERATE OUTPUT "${_controller_script}"
    CONTENT "#!${Python_EXECUTABLE}\nimport sys\n\nfrom ${PROJECT_NAME}.${PROJECT_NAME}_node import main\n
sys.exit(main())\n"
    FILE_PERMISSIONS OWNER_READ OWNER_WRITE OWNER_EXECUTE GROUP_READ GROUP_EXECUTE WORLD_READ
                     WORLD_EXECUTE)
  install(PROGRAMS "${_controller_script}" DESTINATION lib/${PROJECT_NAME})
endmacro()
