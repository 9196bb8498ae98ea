/* Runs an AVR firmware on simavr (an ATmega328P at 8 MHz unless the ELF names its chip) until it sleeps with
 * interrupts off; prints the cycles it ran, on stdout's last line. */
#include <stdio.h>
#include <string.h>

#include <simavr/sim_avr.h>
#include <simavr/sim_elf.h>

int main(int argc, char **argv) {
    elf_firmware_t firmware;
    avr_t *avr;
    int state;
    if (argc != 2 || elf_read_firmware(argv[1], &firmware) != 0) {
        fprintf(stderr, "usage: %s FIRMWARE.elf\n", argv[0]);
        return 2;
    }
    if (!firmware.mmcu[0]) {
        strcpy(firmware.mmcu, "atmega328p");
        firmware.frequency = 8000000;
    }
    avr = avr_make_mcu_by_name(firmware.mmcu);
    if (!avr || avr_init(avr) != 0) return 2;
    avr_load_firmware(avr, &firmware);
    do state = avr_run(avr);
    while (state != cpu_Done && state != cpu_Crashed);
    printf("\n%llu\n", (unsigned long long)avr->cycle);
    return state == cpu_Crashed;
}
