"""Files of the shared data sets that several test modules walk through."""

#: Every shared battery tester's file (under ``../shared/data``), one pack each as a new
#: user would add it.
TESTER_FILES = ["cyclers/maccor/maccor_001.txt",
                "cyclers/biologic/jdb11-1_c3_gcpl_5cycles_2V-3p8V_C-24_data_C09.mpr",
                "cyclers/neware/test_2.ndax", "cyclers/neware/TestFile.nda",
                "cyclers/arbin/20160805_test001_45_cc_01.res",
                "cyclers/arbin/arbin_example.res", "cyclers/arbin/arbin_example.csv",
                "cyclers/arbin/bs542_004_gr_li_50ua_50mv_1v_191020_Channel_11.xlsx"]

#: Their file names (test ids).
TESTER_IDS = [name.split("/")[-1] for name in TESTER_FILES]
