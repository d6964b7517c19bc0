# ROS layer of adroit_pneumatics: the ROS-free pool library, the pool node and nodelet,
# the excitation node, the rosbag -> CSV tool for identification, the rosbag force-tracking
# audit, and their tests.
# Included at the end of CMakeLists.txt (after catkin_package and the core target).

# ROS-free: CylinderPool, PoolGroup, default pool split, model cylinder table
# (adroit_description's library, no ROS library).
find_package(catkin REQUIRED COMPONENTS adroit_core adroit_description)
add_library(adroit_pneumatics_pool src/pool.cpp src/pool_group.cpp)
target_include_directories(adroit_pneumatics_pool PUBLIC include ${catkin_INCLUDE_DIRS})
target_link_libraries(adroit_pneumatics_pool PUBLIC adroit_pneumatics_core ${catkin_LIBRARIES})

# The ROS targets below: adroit_ros (typed parameters, diagnostics, rejection counters) and roscpp & co.
find_package(catkin REQUIRED COMPONENTS
  adroit_core adroit_description adroit_msgs adroit_ros roscpp roslib nodelet pluginlib diagnostic_msgs rosbag std_msgs)

# One ROS wrapper class (pool_ros.cpp, a group of one or more pools; its parameters in
# pool_params.cpp) behind both the nodelet plugin and the node.
add_library(adroit_pneumatics_nodelets nodes/pool_ros.cpp nodes/pool_params.cpp nodes/pool_nodelet.cpp)
target_include_directories(adroit_pneumatics_nodelets PRIVATE ${catkin_INCLUDE_DIRS})
target_link_libraries(adroit_pneumatics_nodelets adroit_pneumatics_pool ${catkin_LIBRARIES})
add_dependencies(adroit_pneumatics_nodelets ${catkin_EXPORTED_TARGETS})

add_executable(pool_node nodes/pool_node.cpp)
target_include_directories(pool_node PRIVATE ${catkin_INCLUDE_DIRS})
target_link_libraries(pool_node adroit_pneumatics_nodelets ${catkin_LIBRARIES})

add_executable(excitation_node nodes/excitation_node.cpp)
target_include_directories(excitation_node PRIVATE ${catkin_INCLUDE_DIRS})
target_link_libraries(excitation_node adroit_pneumatics_pool ${catkin_LIBRARIES})
add_dependencies(excitation_node ${catkin_EXPORTED_TARGETS})

add_executable(pneumatic_sysid_bag nodes/sysid_bag.cpp)
target_include_directories(pneumatic_sysid_bag PRIVATE ${catkin_INCLUDE_DIRS})
target_link_libraries(pneumatic_sysid_bag adroit_pneumatics_pool ${catkin_LIBRARIES})
add_dependencies(pneumatic_sysid_bag ${catkin_EXPORTED_TARGETS})

add_executable(force_tracking_audit nodes/force_audit_bag.cpp)
target_include_directories(force_tracking_audit PRIVATE ${catkin_INCLUDE_DIRS})
target_link_libraries(force_tracking_audit adroit_pneumatics_pool ${catkin_LIBRARIES})
add_dependencies(force_tracking_audit ${catkin_EXPORTED_TARGETS})

install(TARGETS adroit_pneumatics_pool adroit_pneumatics_nodelets
  ARCHIVE DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION}
  LIBRARY DESTINATION ${CATKIN_PACKAGE_LIB_DESTINATION})
install(TARGETS pool_node excitation_node pneumatic_sysid_bag force_tracking_audit
  RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
install(FILES nodelet_plugins.xml DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
install(DIRECTORY launch DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
catkin_install_python(PROGRAMS test/pool_rostest.py DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

if(CATKIN_ENABLE_TESTING)
  catkin_add_gtest(test_pool test/test_pool.cpp)
  target_link_libraries(test_pool adroit_pneumatics_pool GTest::gtest_main)
  # The generated scenes of adroit_description (for the default split on the real model).
  target_compile_definitions(test_pool PRIVATE ADROIT_DESCRIPTION_SHARE="${adroit_description_DIR}/..")
  catkin_add_gtest(test_pool_group test/test_pool_group.cpp)
  target_link_libraries(test_pool_group adroit_pneumatics_pool GTest::gtest_main)
  # Its own binary: it replaces the global operator new/delete to count allocations.
  catkin_add_gtest(test_pool_realtime test/test_pool_realtime.cpp)
  target_link_libraries(test_pool_realtime adroit_pneumatics_pool GTest::gtest_main)

  # The audit tool end to end on bags written with the rosbag API.
  catkin_add_gtest(test_force_audit_bag test/test_force_audit_bag.cpp)
  target_include_directories(test_force_audit_bag PRIVATE ${catkin_INCLUDE_DIRS})
  target_link_libraries(test_force_audit_bag adroit_pneumatics_pool ${catkin_LIBRARIES} GTest::gtest_main)
  add_dependencies(test_force_audit_bag force_tracking_audit ${catkin_EXPORTED_TARGETS})
  target_compile_definitions(test_force_audit_bag PRIVATE ADROIT_DESCRIPTION_SHARE="${adroit_description_DIR}/.."
                             FORCE_AUDIT_BINARY="$<TARGET_FILE:force_tracking_audit>")

  find_package(rostest REQUIRED)
  add_rostest(test/pool.test DEPENDENCIES pool_node)
  add_rostest(test/pool_nodelet.test DEPENDENCIES adroit_pneumatics_nodelets)
  add_rostest(test/pool_group.test DEPENDENCIES pool_node)
endif()
