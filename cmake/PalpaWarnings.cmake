# Warnings-as-errors for palpa's own targets (house style §15). Applied per target so that
# third-party headers included as SYSTEM stay out of it.
function(palpa_warnings target)
  target_compile_options(${target} PRIVATE
    -Wall -Wextra -Wpedantic -Wshadow -Wundef -Wimplicit-fallthrough -Wconversion
    -Wsign-conversion -Wnon-virtual-dtor -Wold-style-cast -Werror)
endfunction()

# shared/ and the servo loop are compiled without exceptions and RTTI: they must not need them.
function(palpa_rt_flags target)
  target_compile_options(${target} PRIVATE -fno-exceptions -fno-rtti)
endfunction()
