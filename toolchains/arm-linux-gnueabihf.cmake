# Cross toolchain for armhf boards (Debian 12: g++-arm-linux-gnueabihf, multiarch :armhf -dev packages).
# Sets only the compiler, the multiarch search paths and the emulator that runs target binaries.
set(CMAKE_SYSTEM_NAME Linux)
set(CMAKE_SYSTEM_PROCESSOR arm)
set(PALPA_TRIPLE arm-linux-gnueabihf)
set(CMAKE_C_COMPILER   ${PALPA_TRIPLE}-gcc)
set(CMAKE_CXX_COMPILER ${PALPA_TRIPLE}-g++)
set(CMAKE_FIND_ROOT_PATH /usr/${PALPA_TRIPLE} /usr/lib/${PALPA_TRIPLE})
set(CMAKE_FIND_ROOT_PATH_MODE_PROGRAM NEVER)
set(CMAKE_FIND_ROOT_PATH_MODE_LIBRARY ONLY)
# Multiarch headers live in the shared /usr/include.
set(CMAKE_FIND_ROOT_PATH_MODE_INCLUDE BOTH)
set(CMAKE_FIND_ROOT_PATH_MODE_PACKAGE BOTH)
set(CMAKE_LIBRARY_ARCHITECTURE ${PALPA_TRIPLE})
set(ENV{PKG_CONFIG_LIBDIR} /usr/lib/${PALPA_TRIPLE}/pkgconfig:/usr/share/pkgconfig)
set(ENV{PKG_CONFIG_SYSROOT_DIR} "")
# -L / (one libc set, the multiarch one); -L /usr/${PALPA_TRIPLE} mixes two ld.so/libc builds and hangs.
set(CMAKE_CROSSCOMPILING_EMULATOR qemu-arm;-L;/)
