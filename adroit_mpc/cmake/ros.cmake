# The ROS side of adroit_mpc, included by CMakeLists.txt before the ROS-free core is built:
# dependencies, dynamic_reconfigure generation (must precede catkin_package), catkin_package,
# and adroit_mpc_ros_targets() for the node and the rostests (called once the core exists).
set(ADROIT_MPC_ROS_DEPS roscpp std_msgs std_srvs sensor_msgs nav_msgs geometry_msgs diagnostic_msgs
  visualization_msgs interactive_markers dynamic_reconfigure adroit_msgs adroit_ros)
find_package(catkin REQUIRED COMPONENTS adroit_core adroit_description ${ADROIT_MPC_ROS_DEPS})

generate_dynamic_reconfigure_options(cfg/Mpc.cfg)

catkin_package(
  INCLUDE_DIRS include
  LIBRARIES adroit_mpc_core
  CATKIN_DEPENDS adroit_core adroit_description ${ADROIT_MPC_ROS_DEPS})

function(adroit_mpc_ros_targets)
  # Thin node (nodes/, one file per job: mpc_ros.h): parameters, state input, planner thread,
  # control output, services, markers, diagnostics.
  file(GLOB node_sources CONFIGURE_DEPENDS nodes/*.cpp)
  add_executable(adroit_mpc ${node_sources})
  target_include_directories(adroit_mpc PRIVATE nodes ${catkin_INCLUDE_DIRS})
  target_link_libraries(adroit_mpc adroit_mpc_core ${catkin_LIBRARIES} Threads::Threads)
  add_dependencies(adroit_mpc ${PROJECT_NAME}_gencfg ${catkin_EXPORTED_TARGETS})
  install(TARGETS adroit_mpc RUNTIME DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})
  install(DIRECTORY launch DESTINATION ${CATKIN_PACKAGE_SHARE_DESTINATION})
  # rostest finds the python test node like rosrun does: installed with the package.
  catkin_install_python(PROGRAMS test/test_mpc_lockstep.py test/test_mpc_pneumatic.py test/test_mpc_typing_lockstep.py DESTINATION ${CATKIN_PACKAGE_BIN_DESTINATION})

  if(CATKIN_ENABLE_TESTING)
    find_package(rostest REQUIRED)
    # Closed loop with the simulation driver in lockstep, and the node's bad-input answers.
    add_rostest(test/mpc_lockstep.test DEPENDENCIES adroit_mpc)
    # Pneumatic mode in real time with the pools: references, tracking, no watchdog trip.
    add_rostest(test/mpc_pneumatic.test DEPENDENCIES adroit_mpc)
    # Typing through the node in lockstep: the keys of a sequence registered in order.
    add_rostest(test/mpc_typing_lockstep.test DEPENDENCIES adroit_mpc)
  endif()
endfunction()
