# CMake toolchain file used through the environment variable CMAKE_TOOLCHAIN_FILE
# (CMake >= 3.21 reads it when a build directory is first configured). Set by scripts/bootstrap.sh.
#
# Why: the ROS 2 Jazzy message wheels on PyPI were built in a container whose Python lived under
# /opt/python/cp311-cp311. Their exported CMake targets
# (share/<msg_pkg>/cmake/export_*__rosidl_generator_pyExport.cmake) still name
#   /opt/python/cp311-cp311/include/python3.11
#   /opt/python/cp311-cp311/lib/python3.11/site-packages/numpy/_core/include
# in INTERFACE_INCLUDE_DIRECTORIES. CMake refuses to generate when an imported target names a
# directory that does not exist, so any rosidl_generate_interfaces() that depends on std_msgs,
# geometry_msgs, builtin_interfaces... fails on a clean machine.
#
# What: at the very end of configuring the top-level directory (cmake_language(DEFER)), walk every
# directory's IMPORTED_TARGETS and drop the INTERFACE_INCLUDE_DIRECTORIES entries that start with
# /opt/python/ and do not exist. Nothing is lost: the generated libraries already carry the real
# Python and NumPy include directories. No root, no edit of installed files, survives reinstalls.
# A build directory configured without this file must be deleted once.
#
# This file sets no compiler: CMake picks the host toolchain exactly as without it.

cmake_minimum_required(VERSION 3.21)

# The toolchain file is read by every project()/enable_language() and by try_compile() projects;
# register the deferred fix once per directory tree.
get_property(_iceskate_fix_registered GLOBAL PROPERTY ICESKATE_OPT_PYTHON_FIX_REGISTERED)
if(NOT _iceskate_fix_registered)
  set_property(GLOBAL PROPERTY ICESKATE_OPT_PYTHON_FIX_REGISTERED TRUE)

  function(_iceskate_collect_directories dir out_var)
    set(_dirs "${dir}")
    get_property(_subdirs DIRECTORY "${dir}" PROPERTY SUBDIRECTORIES)
    foreach(_sub IN LISTS _subdirs)
      _iceskate_collect_directories("${_sub}" _sub_dirs)
      list(APPEND _dirs ${_sub_dirs})
    endforeach()
    set(${out_var} "${_dirs}" PARENT_SCOPE)
  endfunction()

  function(_iceskate_strip_missing_opt_python_includes)
    _iceskate_collect_directories("${CMAKE_SOURCE_DIR}" _dirs)
    set(_fixed 0)
    foreach(_dir IN LISTS _dirs)
      get_property(_targets DIRECTORY "${_dir}" PROPERTY IMPORTED_TARGETS)
      foreach(_target IN LISTS _targets)
        # Imported targets of a subdirectory are not visible here unless GLOBAL.
        if(NOT TARGET "${_target}")
          continue()
        endif()
        get_target_property(_incs "${_target}" INTERFACE_INCLUDE_DIRECTORIES)
        if(NOT _incs)
          continue()
        endif()
        set(_kept "")
        set(_changed FALSE)
        foreach(_inc IN LISTS _incs)
          if(_inc MATCHES "^/opt/python/" AND NOT EXISTS "${_inc}")
            set(_changed TRUE)
          else()
            list(APPEND _kept "${_inc}")
          endif()
        endforeach()
        if(_changed)
          set_property(TARGET "${_target}" PROPERTY INTERFACE_INCLUDE_DIRECTORIES "${_kept}")
          math(EXPR _fixed "${_fixed} + 1")
        endif()
      endforeach()
    endforeach()
    if(_fixed GREATER 0)
      message(STATUS "iceskate toolchain fix: dropped missing /opt/python include dirs "
                     "from ${_fixed} imported target(s)")
    endif()
  endfunction()

  cmake_language(DEFER DIRECTORY "${CMAKE_SOURCE_DIR}"
    CALL _iceskate_strip_missing_opt_python_includes)
endif()
unset(_iceskate_fix_registered)
