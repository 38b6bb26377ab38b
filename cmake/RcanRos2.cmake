# The ROS 2 driver (src/drivers/ros2, docs/DRIVERS.md): Eclipse Cyclone DDS and the ROS 2
# message types, generated at build time by Cyclone's IDL compiler (idlc, package
# cyclonedds-tools) from src/drivers/ros2/idl. Its own library, rcan_ros2, linked into rcand
# (and the ROS 2 tests, benchmark and example): nothing else in the project depends on Cyclone.
find_package(CycloneDDS REQUIRED)
find_program(RCAN_IDLC idlc REQUIRED)

set(RCAN_ROS2_IDL_DIR ${PROJECT_SOURCE_DIR}/src/drivers/ros2/idl)
set(RCAN_ROS2_GEN_DIR ${PROJECT_BINARY_DIR}/generated/ros2)
file(GLOB RCAN_ROS2_IDL_FILES CONFIGURE_DEPENDS ${RCAN_ROS2_IDL_DIR}/*.idl)
file(MAKE_DIRECTORY ${RCAN_ROS2_GEN_DIR})
set(RCAN_ROS2_GENERATED "")
foreach(idl ${RCAN_ROS2_IDL_FILES})
  get_filename_component(n ${idl} NAME_WE)
  # -t: no XTypes type information (ROS 2's rmw_cyclonedds_cpp sends none; types match by
  # name); -x final: plain CDR (XCDR1), as ROS 2 writes it.
  add_custom_command(OUTPUT ${RCAN_ROS2_GEN_DIR}/${n}.c ${RCAN_ROS2_GEN_DIR}/${n}.h
    COMMAND ${RCAN_IDLC} -t -x final -I ${RCAN_ROS2_IDL_DIR} -o ${RCAN_ROS2_GEN_DIR} ${idl}
    DEPENDS ${RCAN_ROS2_IDL_FILES}
    COMMENT "idlc ${n}.idl")
  list(APPEND RCAN_ROS2_GENERATED ${RCAN_ROS2_GEN_DIR}/${n}.c)
endforeach()
# The generated C compiles as C++: built by the project's compiler (no second toolchain
# for the sanitizer and fuzzing trees), without the project's warnings; C11's _Alignof
# (Cyclone's dds_alignof) is C++'s alignof.
set_source_files_properties(${RCAN_ROS2_GENERATED} PROPERTIES LANGUAGE CXX
  COMPILE_OPTIONS "-Wno-deprecated-enum-enum-conversion;-Wno-deprecated;-D_Alignof=alignof")
add_library(rcan_ros2_msgs STATIC ${RCAN_ROS2_GENERATED})
target_include_directories(rcan_ros2_msgs SYSTEM PUBLIC ${RCAN_ROS2_GEN_DIR})
target_link_libraries(rcan_ros2_msgs PUBLIC CycloneDDS::ddsc)

rcan_add_library(rcan_ros2 src/drivers/ros2 ros2_convert.cpp ros2_driver.cpp)
target_include_directories(rcan_ros2 PUBLIC ${PROJECT_SOURCE_DIR}/src)
target_link_libraries(rcan_ros2 PUBLIC rcan_node_safety rcan_config rcan_runtime rcan_ros2_msgs)

# examples/ros2_sim_base: the simulated robot as a ROS 2 robot on DDS (docs/DRIVERS.md), for
# watching the chain without hardware; the end-to-end test drives it through rcand.
add_executable(ros2_sim_base ${PROJECT_SOURCE_DIR}/examples/ros2_sim_base/main.cpp)
set_target_properties(ros2_sim_base PROPERTIES RUNTIME_OUTPUT_DIRECTORY ${PROJECT_BINARY_DIR}/bin)
target_link_libraries(ros2_sim_base PRIVATE rcan_ros2 rcan_node_safety rcan_warnings)
